/* scene_checks.h -- vibromodel.parameters.validate for the native FMUs (see scene_checks.c). */
#ifndef SCENE_CHECKS_H
#define SCENE_CHECKS_H

#include <stddef.h>

#include "rules.h"  /* SCENE_SIZE, SCENE_NAMES, the rules' constants and texts (generated) */

/* scene[] in vibromodel.parameters.scene_names() order.  -1 when the scene is valid; else the index of the
   first parameter that is not, with the ParameterError's reason in reason[]. */
int vibro_scene_check(const double scene[SCENE_SIZE], char *reason, size_t size);

#endif
