/* The closed loop's two parts (the plant's and the controller's model.c, each compiled in its own
 * translation unit, plant_part.c and controller_part.c, with its own config.h and model.h): what
 * the closed loop's model.c may do with a part's Data, held as opaque bytes in its ModelState so
 * that the glue copies and restores both parts with the rest of the closed loop's state. */
#ifndef PARTS_H
#define PARTS_H

#include <stdint.h>

#define PART_BYTES 16384 /* >= sizeof a part's Data (checked when the part is compiled) */

typedef union {
    unsigned char bytes[PART_BYTES];
    double align_double;
    int64_t align_int;
} PartData;

#define DECLARE_PART(p)                                                                            \
    void p##_part_start(PartData *d, double start_time);                                           \
    void p##_part_set_real(PartData *d, int vr, double value);                                     \
    void p##_part_set_int(PartData *d, int vr, int value);                                         \
    void p##_part_set_string(PartData *d, int vr, const char *value);                              \
    double p##_part_get_real(const PartData *d, int vr);                                           \
    int p##_part_initialize(PartData *d, char *msg);                                               \
    int p##_part_step(PartData *d, double t, double h, char *msg);                                 \
    int p##_part_check_tunable(const PartData *d, char *msg);                                      \
    int p##_part_check_state(const PartData *d, char *msg);

DECLARE_PART(plant)
DECLARE_PART(controller)

#endif
