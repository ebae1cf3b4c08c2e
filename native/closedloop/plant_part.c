/* The plant of the closed loop: native/plant/model.c unchanged, with its own config.h and model.h
 * (shipped in the closed-loop FMU as plant_config.h, plant_model.h, plant_model.c). */
#define PART_TABLE plant_part
#define MODEL_CONFIG_HEADER "plant_config.h"
#define MODEL_STATE_HEADER "plant_model.h"
#define PART_MODEL_SOURCE "plant_model.c"
#include "part_api.h"
