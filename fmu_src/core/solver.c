/*
 * solver.c -- the compiled core's solvers' ops and their table (solver.h), in the order of VK_SOLVER_LIST.
 */
#include "solver.h"

/* vk_<name>_ops: each solver's ops (solver.h's VK_OPS_<name>) */
#define VK_DEFINE_OPS(name) const VkSolverOps vk_##name##_ops = VK_OPS_##name;
VK_SOLVER_LIST(VK_DEFINE_OPS)
#undef VK_DEFINE_OPS

#define VK_OPS_ADDRESS(name) &vk_##name##_ops,
const VkSolverOps *const vk_solvers[] = {VK_SOLVER_LIST(VK_OPS_ADDRESS)};
const int vk_n_solvers = sizeof vk_solvers / sizeof vk_solvers[0];
