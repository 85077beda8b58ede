/*
 * scene_checks.c -- vibromodel.parameters.validate's check between parameters, which the table of rules
 * (rules.h, checked by fmi2_native.c before a model starts) cannot express: x_start inside the electrodes.
 * The texts are vibromodel/messages.py's, generated into rules.h (RULE_TEXT_*).
 */
#include "scene_checks.h"

#include <stdio.h>

#include "rules.h"

int vibro_gaps_check(double x_start, double R, char *reason, size_t size)
{
    /* parameters.electrode_gaps: 1 - 2x/(3R), 1 + 2x/(3R) */
    const double u = 2.0 * x_start / (3.0 * R), upper = 1.0 - u, lower = 1.0 + u;
    if (upper <= RULE_PULL_IN_GAP) {
        snprintf(reason, size, RULE_TEXT_PULL_IN_START, 1.5 * R, upper);
        return 0;
    }
    if (lower <= RULE_PULL_IN_GAP) {
        snprintf(reason, size, RULE_TEXT_LOWER_START, -1.5 * R, lower);
        return 0;
    }
    return 1;
}
