/* scene_checks.h -- the checks of vibromodel.parameters.validate beyond the table of rules (see scene_checks.c). */
#ifndef SCENE_CHECKS_H
#define SCENE_CHECKS_H

#include <stddef.h>

/* x_start inside the electrodes (parameters.validate after check_parameters): 1 if it is; else 0 with the
   ParameterError's reason for x_start in reason[]. */
int vibro_gaps_check(double x_start, double R, char *reason, size_t size);

#endif
