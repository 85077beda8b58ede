/*
 * solver.c -- the table of the compiled core's solvers (solver.h), in the order of VK_SOLVER_LIST.
 */
#include "solver.h"

#define VK_OPS_ADDRESS(name) &vk_##name##_ops,
const VkSolverOps *const vk_solvers[] = {VK_SOLVER_LIST(VK_OPS_ADDRESS)};
const int vk_n_solvers = sizeof vk_solvers / sizeof vk_solvers[0];
