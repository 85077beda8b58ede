/*
 * model.h -- the plant's forces and acceleration in C: exact Eq. 3 (fidelity 0) and the polynomial Eq. 7
 * (fidelities 1, 2), the twins of vibromodel/forces.py and models.py (the same operations in the same order).
 * Each law has one function here: vm_hertz (Hertz contact), vm_electrostatic (two-sided electrostatic force).
 */
#ifndef VIBRO_MODEL_H
#define VIBRO_MODEL_H

#include <stdint.h>

typedef struct {
    double mu, Delta, omega, alpha, beta, gamma, Omega, R;
    double poly[6];              /* a0..a5 of Eq. 7 (polynomial models) */
    double g1[6], g2[6], g3[6];  /* series (5) for the polynomial models' forces and AC term */
    double pull_in_c;            /* 2 / (3R) */
    double pull_in_gap;          /* PULL_IN_GAP */
    int64_t polynomial;          /* 0: exact Eq. 3 with events; 1: Eq. 7 (no events) */
    int64_t load_forcing;        /* Delta != 0 */
    int64_t electrostatics;      /* exact: alpha, beta or gamma != 0; polynomial: beta or gamma != 0 */
    int64_t ac;                  /* beta or gamma != 0 */
} VkModel;

/* 1 + 2x/3 = z/z_s: positive in contact (forces.contact_indentation) */
double vm_contact_indentation(double x);
/* The contact flag at a state (x, v, x'' = a): in contact where the indentation is positive; exactly on the contact
   surface (x = -3/2) the motion decides: moving in (v > 0), or at rest with x'' > 0 (about to indent) -- so a start
   at rest on the surface that the forces push in is in contact from its first point (forces.in_contact) */
int vm_in_contact(double x, double v, double a);
/* Hertz contact force (1 + 2x/3)^(3/2) of Eq. 3, 0 without contact (forces.hertz) */
double vm_hertz(double x);
/* alpha F2(x) + (beta sin Omega t + gamma (1 - cos 2 Omega t)) F3(x) of Eq. 3 (forces.electrostatic) */
double vm_electrostatic(const VkModel *m, double t, double x, int *fault);
/* x'' of the model at input U (ExactModel / PolynomialModel accel); *fault as pyfloat.h */
double vm_accel(const VkModel *m, double t, double x, double v, double U, int *fault);
/* cos 2 Omega t from s = sin Omega t as the model computes it: 1 - 2 s^2 (forces.cos_double_angle), within about
   11 units of 2^-53 of libm's cos(2 Omega t) at the same angle Omega t, and one libm call per time instead of two */
static inline double vm_cos_double_angle(double s) { return 1.0 - 2.0 * (s * s); }
/* The time functions of the drive terms at t: cos(omega t), sin(Omega t), cos(2 Omega t), as the model computes
   them (the controller's regressor has the first two: the closed loop evaluates them once per stage) */
typedef struct {
    double cos_omega_t, sin_Omega_t, cos_2Omega_t;
} VmDrive;
/* The drive's time functions at t that the model's terms read (cos omega t with load forcing; sin Omega t and
   cos 2 Omega t with the AC drive; the others 0), each the bits vm_accel computes: 1, or 0 (drive unusable) when one
   of them faults -- vm_accel then says which fault comes first */
int vm_drive_at(const VkModel *m, double t, VmDrive *drive);
/* vm_accel with the drive's time functions given (drive == NULL: computed, as vm_accel) */
double vm_accel_driven(const VkModel *m, double t, const VmDrive *drive, double x, double v, double U, int *fault);
/* (F_contact, F_electrostatic) as they enter the model's equation (model.forces); returns a fault */
int vm_forces(const VkModel *m, double t, double x, double *f_contact, double *f_electrostatic);
/* x'' at input U and (F_contact, F_electrostatic) at one point, the outputs unwritten on a fault: the bits of
   vm_accel and vm_forces and the first fault of the two (vm_accel's first); the exact model computes the Hertz force
   and the electrostatic force (with its drive terms) once for both */
int vm_outputs(const VkModel *m, double t, double x, double v, double U, double *a, double *f_contact,
               double *f_electrostatic);

#endif
