/* State of the closed loop (PaperClosedLoop-<scenario>): the Data of its two parts, the plant and
 * the controller, as each part's own FMU keeps it (parts.h). The closed loop's parameters are the
 * parts' parameters under the names plant.<name> and controller.<name>; its outputs mirror the
 * parts' outputs (config.h: LINKS). */
#ifndef MODEL_H
#define MODEL_H

#include "parts.h"

typedef struct {
    PartData plant;
    PartData controller;
} ModelState;

#endif
