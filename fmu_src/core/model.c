/*
 * model.c -- forces and acceleration of Eq. 3 and Eq. 7 (model.h), operation for operation as
 * vibromodel/forces.py and models.py.
 */
#include "model.h"

#include <math.h>
#include <stddef.h>

#include "pyfloat.h"

/* Eq. 3: indentation 1 + 2x/3 */
double vm_contact_indentation(double x) { return 1.0 + 2.0 * x / 3.0; }

int vm_in_contact(double x, double v, double a)
{
    const double indentation = vm_contact_indentation(x);
    return indentation > 0.0 || (indentation == 0.0 && (v > 0.0 || (v == 0.0 && a > 0.0)));
}

/* Eq. 3: Hertz law (1 + 2x/3)^(3/2), no tension */
double vm_hertz(double x)
{
    double s = 1.0 + 2.0 * x / 3.0;
    return s > 0.0 ? s * sqrt(s) : 0.0;
}

/* The drive's time functions: given (drive != NULL) or computed here */
static double sin_Omega_t(const VkModel *m, double t, const VmDrive *drive, int *fault)
{
    return drive ? drive->sin_Omega_t : py_sin(m->Omega * t, fault);
}

/* cos 2 Omega t: given, or from s = sin Omega t (vm_cos_double_angle) */
static double cos_2Omega_t(double s, const VmDrive *drive)
{
    return drive ? drive->cos_2Omega_t : vm_cos_double_angle(s);
}

static double cos_omega_t(const VkModel *m, double t, const VmDrive *drive, int *fault)
{
    return drive ? drive->cos_omega_t : py_cos(m->omega * t, fault);
}

int vm_drive_at(const VkModel *m, double t, VmDrive *drive)
{
    int fault = FAULT_NONE;
    drive->cos_omega_t = m->load_forcing ? cos_omega_t(m, t, NULL, &fault) : 0.0;
    drive->sin_Omega_t = m->ac ? sin_Omega_t(m, t, NULL, &fault) : 0.0;
    drive->cos_2Omega_t = m->ac ? vm_cos_double_angle(drive->sin_Omega_t) : 0.0;
    return fault == FAULT_NONE;
}

/* Eq. 3: alpha [(1 - u)^-2 - (1 + u)^-2] + (beta sin Omega t + gamma (1 - cos 2 Omega t)) (1 - u)^-2, u = 2x/(3R) */
static inline __attribute__((always_inline)) double electrostatic(const VkModel *m, double t, const VmDrive *drive, double x, int *fault)
{
    double u = 2.0 * x / (3.0 * m->R);
    double f3 = py_div(1.0, (1.0 - u) * (1.0 - u), fault);
    if (*fault) return 0.0;
    double force = m->alpha * (f3 - py_div(1.0, (1.0 + u) * (1.0 + u), fault));
    if (*fault) return 0.0;
    if (m->ac) {
        double s = sin_Omega_t(m, t, drive, fault);
        double c = cos_2Omega_t(s, drive);
        force += (m->beta * s + m->gamma * (1.0 - c)) * f3;
    }
    return force;
}

double vm_electrostatic(const VkModel *m, double t, double x, int *fault)
{
    return electrostatic(m, t, NULL, x, fault);
}

/* sum c_k x^k for the six coefficients of a series (5) (forces.horner) */
static double horner(const double *c, double x)
{
    double value = 0.0;
    for (int k = 5; k >= 0; k--) value = value * x + c[k];
    return value;
}

/* Eq. 3 with U: x'' = 1 + Delta cos(omega t) + F_em(t, x) - H(x) - mu x' + U (ExactModel accel) */
static inline __attribute__((always_inline)) double exact_accel(const VkModel *m, double t, const VmDrive *drive, double x, double v, double U, int *fault)
{
    double a = 1.0 + U - m->mu * v;
    a -= vm_hertz(x);
    if (m->load_forcing) a += m->Delta * cos_omega_t(m, t, drive, fault);
    if (*fault) return a;
    if (m->electrostatics) a += electrostatic(m, t, drive, x, fault);
    return a;
}

/* Eq. 7 with U (PolynomialModel accel) */
static inline __attribute__((always_inline)) double polynomial_accel(const VkModel *m, double t, const VmDrive *drive, double x, double v, double U,
                               int *fault)
{
    const double *c = m->poly, *g3 = m->g3;
    double acc = U - m->mu * v - (c[0] + x * (c[1] + x * (c[2] + x * (c[3] + x * (c[4] + x * c[5])))));
    if (m->load_forcing) acc += m->Delta * cos_omega_t(m, t, drive, fault);
    if (*fault) return acc;
    if (m->ac) {
        double G3 = g3[0] + x * (g3[1] + x * (g3[2] + x * (g3[3] + x * (g3[4] + x * g3[5]))));
        double s = sin_Omega_t(m, t, drive, fault);
        double c2 = cos_2Omega_t(s, drive);
        acc += (m->beta * s - m->gamma * c2) * G3;
    }
    return acc;
}

/* Inline (always_inline, across files under -flto; an external definition all the same, model.h declaring it
   plainly): the plant's right-hand side calls it once per stage (plant.c) */
inline __attribute__((always_inline)) double vm_accel_driven(const VkModel *m, double t, const VmDrive *drive, double x,
                                                             double v, double U, int *fault)
{
    *fault = FAULT_NONE;
    return m->polynomial ? polynomial_accel(m, t, drive, x, v, U, fault) : exact_accel(m, t, drive, x, v, U, fault);
}

double vm_accel(const VkModel *m, double t, double x, double v, double U, int *fault)
{
    return vm_accel_driven(m, t, NULL, x, v, U, fault);
}

int vm_outputs(const VkModel *m, double t, double x, double v, double U, double *a, double *f_contact,
               double *f_electrostatic)
{
    int fault = FAULT_NONE;
    if (m->polynomial) {  /* Eq. 7: its x'' and its forces are different series */
        double acc = vm_accel(m, t, x, v, U, &fault);
        if (!fault) fault = vm_forces(m, t, x, f_contact, f_electrostatic);
        if (!fault) *a = acc;
        return fault;
    }
    /* exact_accel's operations in its order, with the Hertz force and electrostatic() (drive NULL, as vm_forces)
       each computed once for x'' and the outputs: the same bits as vm_accel then vm_forces, and the same first
       fault (the cos of omega t comes first in both; electrostatic() faults alike for x'' and the forces) */
    double hertz = vm_hertz(x), acc = 1.0 + U - m->mu * v;
    acc -= hertz;
    if (m->load_forcing) acc += m->Delta * cos_omega_t(m, t, NULL, &fault);
    if (fault) return fault;
    double electric = electrostatic(m, t, NULL, x, &fault);
    if (fault) return fault;
    if (m->electrostatics) acc += electric;
    *a = acc;
    *f_contact = hertz;
    *f_electrostatic = electric;
    return FAULT_NONE;
}

int vm_forces(const VkModel *m, double t, double x, double *f_contact, double *f_electrostatic)
{
    int fault = FAULT_NONE;
    if (!m->polynomial) {  /* ExactModel.forces */
        *f_contact = vm_hertz(x);
        *f_electrostatic = vm_electrostatic(m, t, x, &fault);
        return fault;
    }
    /* PolynomialModel.forces: G1(x), alpha G2(x) + drive G3(x) of the series (5) */
    double s = py_sin(m->Omega * t, &fault);
    double c = vm_cos_double_angle(s);
    double drive = m->beta * s + m->gamma * (1.0 - c);
    *f_contact = horner(m->g1, x);
    *f_electrostatic = m->alpha * horner(m->g2, x) + drive * horner(m->g3, x);
    return fault;
}
