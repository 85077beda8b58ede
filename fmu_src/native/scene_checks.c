/*
 * scene_checks.c -- vibromodel.parameters.validate(scene) for the native FMUs: the same checks in the same
 * order with the same texts (the fixed ones from rules.h, generated from vibromodel; the two pull-in texts
 * formatted here as parameters.py formats them, :g and .3g being C's %g and %.3g).
 */
#include "scene_checks.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static const char *const NAMES[SCENE_SIZE] = SCENE_NAMES;

static int index_of(const char *name)
{
    for (int i = 0; i < SCENE_SIZE; i++)
        if (strcmp(NAMES[i], name) == 0) return i;
    return -1;
}

int vibro_scene_check(const double scene[SCENE_SIZE], char *reason, size_t size)
{
    for (int i = 0; i < SCENE_SIZE; i++)
        if (!isfinite(scene[i])) { snprintf(reason, size, "%s", RULE_FINITE); return i; }
    const int iR = index_of("R"), ix = index_of("x_start");
    const double R = scene[iR];
    if (R <= 0) { snprintf(reason, size, "%s", RULE_R_POSITIVE); return iR; }
    static const char *const nonnegative[] = {"mu", "alpha", "gamma"};
    for (int k = 0; k < 3; k++) {
        int i = index_of(nonnegative[k]);
        if (scene[i] < 0) { snprintf(reason, size, "%s", RULE_NONNEGATIVE); return i; }
    }
    static const char *const frequencies[] = {"omega", "Omega"};
    for (int k = 0; k < 2; k++) {
        int i = index_of(frequencies[k]);
        if (!(0.0 <= scene[i] && scene[i] <= RULE_MAX_FREQUENCY)) { snprintf(reason, size, "%s", RULE_FREQUENCY); return i; }
    }
    /* parameters.electrode_gaps: 1 - 2x/(3R), 1 + 2x/(3R) */
    const double u = 2.0 * scene[ix] / (3.0 * R), upper = 1.0 - u, lower = 1.0 + u;
    if (upper <= RULE_PULL_IN_GAP) {
        snprintf(reason, size, "at or beyond pull-in x = 3R/2 = %g (gap 1-2x/(3R) = %.3g)", 1.5 * R, upper);
        return ix;
    }
    if (lower <= RULE_PULL_IN_GAP) {
        snprintf(reason, size, "at or beyond the lower electrode x = -3R/2 = %g (gap 1+2x/(3R) = %.3g)", -1.5 * R,
                 lower);
        return ix;
    }
    return -1;
}
