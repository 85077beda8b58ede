/* numbalsoda_driver.c -- numbalsoda's compiled solvers (dop853_wrapper of libdop853.so, lsoda_wrapper of liblsoda.so) on a C
 * right-hand side equal to vibrofmu.speed.peers.accel (the function numba compiles for `vibrofmu bench --peers`), for
 * valgrind's callgrind: --toggle-collect=nb_run counts the solver and the right-hand side of one run, and
 * --dump-after=nb_done writes one profile per run (vibrofmu.speed.peer_instructions).
 *
 * Usage: numbalsoda_driver LIBRARY SYMBOL X0 V0 MU DELTA OMEGA_LOAD OMEGA ALPHA BETA GAMMA R STOP INTERVAL RTOL...
 * stdout per RTOL: "run RTOL ok SUCCESS X..." (x at 0, INTERVAL, ..., STOP; atol = 1e-2 rtol, at most 10^6 steps). */
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
typedef void (*Rhs)(double, double *, double *, void *);
typedef void (*Wrapper)(Rhs, int, double *, double *, int, double *, double *, double, double, int, int *);
static void rhs(double t, double *u, double *du, void *data)
{
    const double *p = data;
    double x = u[0], v = u[1];
    double a = 1.0 - p[0] * v;
    double s = 1.0 + 2.0 * x / 3.0;
    if (s > 0.0) a -= s * sqrt(s);
    a += p[1] * cos(p[2] * t);
    double w = 2.0 * x / (3.0 * p[7]);
    double f3 = 1.0 / ((1.0 - w) * (1.0 - w));
    du[0] = v;
    du[1] = a + p[4] * (f3 - 1.0 / ((1.0 + w) * (1.0 + w))) + (p[5] * sin(p[3] * t) + p[6] * (1.0 - cos(2.0 * p[3] * t))) * f3;
}
void nb_run(Wrapper f, double *u0, double *p, int nt, double *t, double *usol, double rtol, int *ok) __attribute__((noinline));
void nb_run(Wrapper f, double *u0, double *p, int nt, double *t, double *usol, double rtol, int *ok)
{
    f(rhs, 2, u0, p, nt, t, usol, rtol, 1e-2 * rtol, 1000000, ok);
    __asm__ volatile("" ::: "memory");
}
void nb_done(void) __attribute__((noinline));
void nb_done(void) { __asm__ volatile("" ::: "memory"); }
int main(int argc, char **argv)
{
    if (argc < 16) {
        fprintf(stderr, "usage: numbalsoda_driver LIBRARY SYMBOL X0 V0 MU DELTA OMEGA_LOAD OMEGA ALPHA BETA GAMMA R STOP "
                        "INTERVAL RTOL...\n");
        return 1;
    }
    void *lib = dlopen(argv[1], RTLD_NOW);
    if (!lib) {
        fprintf(stderr, "%s\n", dlerror());
        return 1;
    }
    Wrapper f = (Wrapper)dlsym(lib, argv[2]);
    if (!f) {
        fprintf(stderr, "no %s in %s\n", argv[2], argv[1]);
        return 1;
    }
    double u0[2] = {atof(argv[3]), atof(argv[4])}, p[8];
    for (int i = 0; i < 8; i++) p[i] = atof(argv[5 + i]);
    double stop = atof(argv[13]), interval = atof(argv[14]);
    int nt = (int)lround(stop / interval) + 1;
    double *t = malloc(sizeof(double) * (size_t)nt), *usol = malloc(sizeof(double) * 2 * (size_t)nt);
    if (!t || !usol) return 1;
    for (int i = 0; i < nt; i++) t[i] = interval * i;
    for (int k = 15; k < argc; k++) {
        int ok = 999;
        double u[2] = {u0[0], u0[1]};
        nb_run(f, u, p, nt, t, usol, atof(argv[k]), &ok);
        nb_done();
        printf("run %s ok %d", argv[k], ok);
        for (int i = 0; i < nt; i++) printf(" %.17g", usol[2 * i]);
        printf("\n");
    }
    free(t);
    free(usol);
    return 0;
}
