/* openloop_plant.c -- see openloop_plant.h. */
#include <math.h>
#include <stddef.h>

#include "fidelity.h"
#include "openloop_plant.h"

/* the level's evaluator (fidelity.h, from the registry): the slow flow's table or the OAFM sums */
static int slow_flow(const OlPlant *p) { return VK_FIDELITIES[p->fidelity].evaluator == VK_EVALUATOR_SLOWFLOW; }

int vk_open_loop_state(const OlPlant *p, double tau, double *xva)
{
    if (slow_flow(p)) return vk_slowflow_state(&p->slowflow, tau, xva) ? OL_BEYOND : 0;
    vk_oafm_state(&p->oafm, tau, xva);
    return 0;
}

int vk_open_loop_do_step(OlPlant *p, double t, double h)
{
    VkPlant *k = &p->plant;
    if (k->error) return (int)k->error;
    double tolerance = k->time_tolerance * (fabs(t) > 1.0 ? fabs(t) : 1.0);  /* plant.check_step */
    if (!(isfinite(h) && h > 0.0) || k->U_input != 0.0 || !(isfinite(t) && fabs(t - k->plant_t) <= tolerance))
        return OL_REFUSED;
    double xva[3];
    if (slow_flow(p)) {
        if (vk_slowflow_state(&p->slowflow, t + h, xva)) return OL_BEYOND;
    } else {
        vk_oafm_step(&p->oafm, t + h, xva);
    }
    double saved[5];  /* a fault or a non-finite output leaves the plant as it was */
    int64_t saved_contact = k->in_contact, saved_enabled = k->enabled;
    for (int i = 0; i < 5; i++) saved[i] = k->out[i];
    int bad = vk_outputs_at(k, t + h, xva[0], xva[1], &xva[2]) != VK_OK;  /* every output at t + h */
    for (int i = 0; i < 5 && !bad; i++) bad = !isfinite(k->out[i]);
    if (bad) {
        for (int i = 0; i < 5; i++) k->out[i] = saved[i];
        k->in_contact = saved_contact;
        k->enabled = saved_enabled;
        k->error = 0;
        return OL_NONFINITE;
    }
    k->plant_t = t + h;
    return 0;
}

void vk_open_loop_layout(int64_t *sizes)
{
    sizes[0] = (int64_t)sizeof(OlPlant);
    sizes[1] = (int64_t)sizeof(OePiece);
    sizes[2] = (int64_t)offsetof(OlPlant, slowflow);
    sizes[3] = (int64_t)offsetof(OlPlant, oafm);
}

int vk_open_loop_run(OlPlant *p, double dt, size_t n, double *x_out, size_t *done)
{
    for (*done = 0; *done < n; ++*done) {
        int code = vk_open_loop_do_step(p, p->plant.plant_t, dt);
        if (code) return code;
        x_out[*done] = p->plant.out[0];
    }
    return 0;
}
