/* The controller of the closed loop: native/controller/model.c unchanged, with its own config.h and model.h
 * (shipped in the closed-loop FMU as controller_config.h, controller_model.h, controller_model.c). */
#define PART_TABLE controller_part
#define MODEL_CONFIG_HEADER "controller_config.h"
#define MODEL_STATE_HEADER "controller_model.h"
#define PART_MODEL_SOURCE "controller_model.c"
#include "part_api.h"
