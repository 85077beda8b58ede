/*
 * solver.c -- the table of the compiled core's solvers (solver.h), in the order of vibromodel/solvers.py's SOLVERS.
 */
#include "solver.h"

const VkSolverOps *const vk_solvers[VK_N_SOLVERS] = {&vk_dop853_ops, &vk_rk4_ops};
