/*
 * cvode_peer.c -- SUNDIALS CVODE on the plant's exact model (fmu_src/core/model.c's vm_accel: the right-hand side
 * the FMUs step), the peer of `vibrofmu bench --peers` (compiled by vibrofmu.speed.peers against SUNDIALS >= 6).
 *
 * Usage: cvode_peer METHOD RTOL ATOL STOP STEP REPEATS mu Delta omega Omega alpha beta gamma R x_start v_start
 *   METHOD: adams (fixed-point iteration) or bdf (Newton, dense direct solver, difference-quotient Jacobian).
 * Each of REPEATS runs: CVodeInit at t = 0, then CVode(CV_NORMAL) to each output n STEP (n = 1 .. STOP/STEP),
 * timed together.  stdout: "loop SECONDS RHS_CALLS" per run, then "x T VALUE" for every output of the last run.
 * Exit code 0, 1 (usage), 2 (CVODE failed; its flag on stderr).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cvode/cvode.h>
#include <nvector/nvector_serial.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunnonlinsol/sunnonlinsol_fixedpoint.h>

#include "model.h"

static long rhs_calls;

static int rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *user)
{
    const VkModel *m = user;
    double *yy = N_VGetArrayPointer(y), *f = N_VGetArrayPointer(ydot);
    int fault;
    rhs_calls++;
    f[0] = yy[1];
    f[1] = vm_accel(m, t, yy[0], yy[1], 0.0, &fault);
    return fault ? -1 : 0;
}

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int main(int argc, char **argv)
{
    if (argc != 17 || (strcmp(argv[1], "adams") && strcmp(argv[1], "bdf"))) {
        fprintf(stderr, "usage: cvode_peer adams|bdf RTOL ATOL STOP STEP REPEATS mu Delta omega Omega alpha beta "
                        "gamma R x_start v_start\n");
        return 1;
    }
    int bdf = strcmp(argv[1], "bdf") == 0, repeats = atoi(argv[6]);
    double rtol = strtod(argv[2], NULL), atol = strtod(argv[3], NULL), stop = strtod(argv[4], NULL);
    double step = strtod(argv[5], NULL), p[10];
    for (int i = 0; i < 10; i++) p[i] = strtod(argv[7 + i], NULL);
    VkModel m;
    memset(&m, 0, sizeof m);  /* the exact model's fields as vibromodel.compiled sets them */
    m.mu = p[0], m.Delta = p[1], m.omega = p[2], m.Omega = p[3], m.alpha = p[4], m.beta = p[5], m.gamma = p[6];
    m.R = p[7];
    m.pull_in_c = 2.0 / (3.0 * m.R);
    m.pull_in_gap = 1e-3;
    m.load_forcing = m.Delta != 0.0;
    m.ac = m.beta != 0.0 || m.gamma != 0.0;
    m.electrostatics = m.alpha != 0.0 || m.ac;
    long n_out = lround(stop / step);
    double *xs = malloc(sizeof(double) * (size_t)n_out), *ts = malloc(sizeof(double) * (size_t)n_out);
    SUNContext ctx;
    if (SUNContext_Create(NULL, &ctx)) return 2;
    for (int r = 0; r < repeats; r++) {
        N_Vector y = N_VNew_Serial(2, ctx);
        N_VGetArrayPointer(y)[0] = p[8];
        N_VGetArrayPointer(y)[1] = p[9];
        rhs_calls = 0;
        double started = now();
        void *mem = CVodeCreate(bdf ? CV_BDF : CV_ADAMS, ctx);
        int flag = CVodeInit(mem, rhs, 0.0, y);
        if (!flag) flag = CVodeSStolerances(mem, rtol, atol);
        if (!flag) flag = CVodeSetUserData(mem, &m);
        if (!flag) flag = CVodeSetMaxNumSteps(mem, 10000000);
        SUNMatrix A = NULL;
        SUNLinearSolver LS = NULL;
        SUNNonlinearSolver NLS = NULL;
        if (!flag && bdf) {
            A = SUNDenseMatrix(2, 2, ctx);
            LS = SUNLinSol_Dense(y, A, ctx);
            flag = CVodeSetLinearSolver(mem, LS, A);
        } else if (!flag) {
            NLS = SUNNonlinSol_FixedPoint(y, 0, ctx);
            flag = CVodeSetNonlinearSolver(mem, NLS);
        }
        for (long n = 0; !flag && n < n_out; n++) {
            double t;
            ts[n] = (double)(n + 1) * step;
            flag = CVode(mem, ts[n], y, &t, CV_NORMAL);
            flag = flag < 0 ? flag : 0;
            xs[n] = N_VGetArrayPointer(y)[0];
        }
        double seconds = now() - started;
        CVodeFree(&mem);
        if (LS) SUNLinSolFree(LS);
        if (A) SUNMatDestroy(A);
        if (NLS) SUNNonlinSolFree(NLS);
        N_VDestroy(y);
        if (flag) {
            fprintf(stderr, "cvode_peer: CVODE failed with flag %d\n", flag);
            return 2;
        }
        printf("loop %.9g %ld\n", seconds, rhs_calls);
    }
    for (long n = 0; n < n_out; n++) printf("x %.17g %.17g\n", ts[n], xs[n]);
    SUNContext_Free(&ctx);
    free(xs);
    free(ts);
    return 0;
}
