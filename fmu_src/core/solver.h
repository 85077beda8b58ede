/*
 * solver.h -- the one interface of the compiled core's solvers, and their list (the C side of
 * vibromodel/solvers.py's SOLVERS: entry k of VK_SOLVER_LIST and vk_solvers is the solver whose `solver` setting
 * is k).
 *
 * A container (plant.c's VkPlant, closedloop.c's VlLoop) holds every solver family's state (Dop853 for the
 * adaptive solvers, Rk4 for the fixed-step ones: pointer-free, so its bytes are the FMU state) and calls the solver
 * of its `solver` setting through the ops, never branching on the solver.  Its doStep is written once on
 * `const VkSolverOps *` (always_inline) and instantiated per solver from VK_SOLVER_LIST with that solver's ops
 * VK_OPS_<name>, a constant there: the compiler resolves and inlines every op, so a doStep costs one indirect call
 * (the container's table of instances, indexed by `solver`); its other operations call through vk_solvers[solver].
 * The hot loops (stages, steps, events) are inside each solver.
 *
 * Adding a solver: its functions in its own .c file (on the Dop853 or Rk4 state), its ops below (adaptors and
 * VK_OPS_<name>), one entry in VK_SOLVER_LIST, one entry in vibromodel/solvers.py.
 */
#ifndef VIBRO_SOLVER_H
#define VIBRO_SOLVER_H

#include <string.h>

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
    /* 1: its error control reads rtol (solvers.SolverEntry.family "adaptive": the tolerance factor of a long, lightly
       damped run applies, models.solver_tolerance); 0: a fixed step */
    int reads_tolerance;
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

/* ---- each solver's ops: adaptors of its functions (core/<name>.h) to the interface, static inline here so that a
   container's per-solver doStep sees them (VK_OPS_<name>: the ops as an initializer) ---- */

/* DOP853 (dop853.c) */
static inline int vk_dop853_restart(VkSolverSlots s, const VkRhs *f, void *context, double t, const double *y,
                                    DopReport *r)
{
    return dop_restart(s.adaptive, f->rhs, context, t, y, r);
}

static inline int vk_dop853_advance(VkSolverSlots s, const VkRhs *f, void *context, double t_target, DopReport *r)
{
    return dop_advance(s.adaptive, f->rhs, context, t_target, r);
}

static inline int vk_dop853_value_at(VkSolverSlots s, const VkRhs *f, void *context, double t, double *y,
                                     DopReport *r)
{
    return dop_value_at(s.adaptive, f->rhs, context, t, y, r);
}

static inline const double *vk_dop853_state(VkSolverSlots s, double *t)
{
    *t = s.adaptive->t;
    return s.adaptive->y;
}

static inline double vk_dop853_max_step(VkSolverSlots s) { return s.adaptive->max_step; }

#define VK_OPS_dop853 {"DOP853", 1, vk_dop853_restart, 1, vk_dop853_advance, vk_dop853_value_at, vk_dop853_state, \
                       vk_dop853_max_step, NULL}

/* RK4 (rk4.c) */
/* Rk4: the state is taken */
static inline int vk_rk4_restart(VkSolverSlots s, const VkRhs *f, void *context, double t, const double *y,
                                 DopReport *r)
{
    (void)f;
    (void)context;
    (void)r;
    s.fixed->t = t;
    memmove(s.fixed->y, y, sizeof(double) * (size_t)s.fixed->n);
    return DOP_OK;
}

/* with the drive's phasors where the container gives them (rk4_advance_phased), else rk4_advance */
static inline int vk_rk4_advance(VkSolverSlots s, const VkRhs *f, void *context, double t_target, DopReport *r)
{
    if (f->phased) {
        double freq[RK4_MAX_PHASES];
        f->frequencies(context, freq);
        return rk4_advance_phased(s.fixed, f->phased, context, f->n_freq, freq, t_target, r);
    }
    return rk4_advance(s.fixed, f->rhs, context, t_target, r);
}

static inline int vk_rk4_value_at(VkSolverSlots s, const VkRhs *f, void *context, double t, double *y, DopReport *r)
{
    (void)f;
    (void)context;
    return rk4_value_at(s.fixed, t, y, r);
}

static inline const double *vk_rk4_state(VkSolverSlots s, double *t)
{
    *t = s.fixed->t;
    return s.fixed->y;
}

static inline double vk_rk4_max_step(VkSolverSlots s) { return s.fixed->max_step; }

#define VK_OPS_rk4 {"RK4", 0, vk_rk4_restart, 0, vk_rk4_advance, vk_rk4_value_at, vk_rk4_state, vk_rk4_max_step, \
                    vk_rk4_drive_gain_x}

/* Every solver, in the order of vibromodel/solvers.py's SOLVERS (position = the `solver` setting): X(name) for each,
   its ops VK_OPS_<name> above (vk_<name>_ops in solver.c).  Adding a solver: one entry here. */
#define VK_SOLVER_LIST(X) X(dop853) X(rk4)

#define VK_DECLARE_OPS(name) extern const VkSolverOps vk_##name##_ops;
VK_SOLVER_LIST(VK_DECLARE_OPS)
#undef VK_DECLARE_OPS

/* A container's doStep per solver, written once: VK_DO_STEP_TABLE(table), with VK_DO_STEP_CONTAINER and
   VK_DO_STEP_GENERIC defined, defines `static int <generic>_<name>(Container *c, double t, double h)` for every
   solver of VK_SOLVER_LIST, each calling generic(c, &ops, t, h) with its ops VK_OPS_<name> as a constant (so the
   compiler resolves and inlines every op of an always_inline generic), and `table`, those functions in the list's
   order (indexed by the solver setting). */
#define VK_DO_STEP_CAT_(a, b) a##_##b
#define VK_DO_STEP_CAT(a, b) VK_DO_STEP_CAT_(a, b)  /* generic_name: one table per generic in a file */
#define VK_DO_STEP_DEFINE(name)                                                                  \
    static int VK_DO_STEP_CAT(VK_DO_STEP_GENERIC, name)(VK_DO_STEP_CONTAINER *c, double t, double h) \
    {                                                                                            \
        static const VkSolverOps ops = VK_OPS_##name;                                            \
        return VK_DO_STEP_GENERIC(c, &ops, t, h);                                                \
    }
#define VK_DO_STEP_ENTRY(name) VK_DO_STEP_CAT(VK_DO_STEP_GENERIC, name),
#define VK_DO_STEP_TABLE(table)                                                   \
    VK_SOLVER_LIST(VK_DO_STEP_DEFINE)                                             \
    static int (*const table[])(VK_DO_STEP_CONTAINER *, double, double) = {VK_SOLVER_LIST(VK_DO_STEP_ENTRY)};

/* The table, indexed by the `solver` setting (0 <= solver < vk_n_solvers: the parameter rules and the FMU state's
   constant bytes keep it there) */
extern const VkSolverOps *const vk_solvers[];
extern const int vk_n_solvers;

#endif
