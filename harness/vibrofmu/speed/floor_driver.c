/*
 * floor_driver.c -- the kernel floor of exact f0 (vibrofmu.speed.instructions.count_kernel_floor): loads a
 * kernel library, reads the bytes of a plant set up by that tree's Python (pointer-free in every version) and
 * runs vk_run over them, so that callgrind (--toggle-collect=vk_run) counts the plant's steps without any FMI
 * layer or Python.  Not an FMI host: it calls the kernel's vk_run only.
 *
 * Usage: floor_driver KERNEL PLANT_BYTES DT N      stdout: "CODE SIZE X_LAST"; exit code: vk_run's (1: usage).
 */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>

int main(int argc, char **argv)
{
    if (argc != 5) {
        fprintf(stderr, "usage: floor_driver KERNEL PLANT_BYTES DT N\n");
        return 1;
    }
    void *lib = dlopen(argv[1], RTLD_NOW);
    int (*run)(void *, double, size_t, double *);
    *(void **)(&run) = lib != NULL ? dlsym(lib, "vk_run") : NULL;
    FILE *f = fopen(argv[2], "rb");
    if (run == NULL || f == NULL) {
        fprintf(stderr, "floor_driver: cannot load vk_run from %s or read %s\n", argv[1], argv[2]);
        return 1;
    }
    static unsigned char plant[1 << 20];
    size_t size = fread(plant, 1, sizeof plant, f);
    fclose(f);
    double dt = strtod(argv[3], NULL);
    size_t n = strtoul(argv[4], NULL, 10);
    double *x = malloc(n * sizeof *x);
    if (x == NULL || n == 0) return 1;
    int code = run(plant, dt, n, x);
    printf("%d %zu %.17g\n", code, size, x[n - 1]);
    return code;
}
