/*
 * solver.h -- the one interface of the compiled core's solvers, and their list (the C side of
 * vibromodel/solvers.py's SOLVERS: entry k of VK_SOLVER_LIST and vk_solvers is the solver whose `solver` setting
 * is k).
 *
 * A container (plant.c's VkPlant, closedloop.c's VlLoop) holds every solver family's state (Dop853 for the
 * adaptive solvers, Rk4 for the fixed-step ones: pointer-free, so its bytes are the FMU state) and calls the solver
 * of its `solver` setting through vk_solvers[solver], never branching on the solver: an indirect call per doStep
 * operation, the hot loops (stages, steps, events) inside each solver.
 *
 * Adding a solver: its ops in its own .c file (on the Dop853 or Rk4 state), one entry in VK_SOLVER_LIST below, one
 * entry in vibromodel/solvers.py.
 */
#ifndef VIBRO_SOLVER_H
#define VIBRO_SOLVER_H

#include "dop853.h"
#include "rk4.h"

/* The solver states of a container: each solver uses its family's (passed by value: two registers) */
typedef struct {
    Dop853 *adaptive;
    Rk4 *fixed;
} VkSolverSlots;

/* The right-hand side of a container (a constant per container; the context, the container itself, is passed
   beside it): rhs always; phased where the time dependence is the drive's phasors (the plant), with n_freq
   (<= RK4_MAX_PHASES) frequencies that frequencies(context, freq) fills in -- a solver may use it instead of rhs
   (RK4 does), or NULL */
typedef struct {
    DopRhs rhs;
    Rk4PhasedRhs phased;
    int n_freq;
    void (*frequencies)(void *context, double *freq);
} VkRhs;

/* Every function returning int gives DOP_OK or DOP_TERMINAL / DOP_FAILED / DOP_RAISED with the report filled. */
typedef struct {
    const char *name;  /* as the notes and logs name it: "DOP853", "RK4" */
    /* start afresh at (t, y[0..n-1]) (Dop853._restart; a fixed-step solver takes the state) */
    int (*restart)(VkSolverSlots s, const VkRhs *f, void *context, double t, const double *y, DopReport *r);
    /* integrator.set_input(t, U) for a held input U that the right-hand side reads: 1 -- if U changed, restart at
       t from the value there (Dop853.set_input); 0 -- U is taken, no restart (Rk4.set_input: each advance ends on
       its target).  A flag, not a call: the plant's doStep asks it every time. */
    int restart_on_input;
    /* integrator.advance(t_target) */
    int (*advance)(VkSolverSlots s, const VkRhs *f, void *context, double t_target, DopReport *r);
    /* integrator.value_at(t): y[0..n-1] at t; DOP_RAISED (ValueError) where the solver holds no value for t */
    int (*value_at)(VkSolverSlots s, const VkRhs *f, void *context, double t, double *y, DopReport *r);
    /* the solver's current time (into *t) and state */
    const double *(*state)(VkSolverSlots s, double *t);
    /* integrator.max_step: its step ceiling (inf: none) */
    double (*max_step)(VkSolverSlots s);
    /* integrate.rk4_drive_gains(theta)[0] for a solver whose ripple of a fast drive is checked at set-up (the
       settings' drive warnings), else NULL */
    double (*drive_gain_x)(double theta);
} VkSolverOps;

/* Every solver, in the order of vibromodel/solvers.py's SOLVERS (position = the `solver` setting): X(name) for each,
   its ops vk_<name>_ops defined in core/<name>.c.  Adding a solver: one entry here. */
#define VK_SOLVER_LIST(X) X(dop853) X(rk4)

#define VK_DECLARE_OPS(name) extern const VkSolverOps vk_##name##_ops;
VK_SOLVER_LIST(VK_DECLARE_OPS)
#undef VK_DECLARE_OPS

/* The table, indexed by the `solver` setting (0 <= solver < vk_n_solvers: the parameter rules and the FMU state's
   constant bytes keep it there) */
extern const VkSolverOps *const vk_solvers[];
extern const int vk_n_solvers;

#endif
