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

/* What the closed loop does with a part: the same functions for both, each on its own Data. */
typedef struct {
    void (*start)(PartData *d, double start_time);
    void (*set_real)(PartData *d, int vr, double value);
    void (*set_int)(PartData *d, int vr, int value);
    void (*set_string)(PartData *d, int vr, const char *value);
    double (*get_real)(const PartData *d, int vr);
    int (*initialize)(PartData *d, char *msg);
    int (*step)(PartData *d, double t, double h, char *msg);
    int (*check_tunable)(const PartData *d, char *msg);
    int (*check_state)(const PartData *d, char *msg);
} Part;

extern const Part plant_part;      /* plant_part.c */
extern const Part controller_part; /* controller_part.c */

#endif
