/*
 * pyloader.h -- make the Python a pythonfmu FMU was built with available in a host that is not Python
 * (see pyloader.c).
 */
#ifndef VIBRO_PYLOADER_H
#define VIBRO_PYLOADER_H

#include <stddef.h>

/* Name of the environment variable that replaces the FMU's recorded Python environment file. */
#define VIBRO_PYTHON_ENV_VARIABLE "VIBROFMU_PYTHON_ENV"
/* The recorded environment file, inside the FMU's resources folder. */
#define VIBRO_PYTHON_ENV_FILE "python_env.txt"

/* Make an initialized Python interpreter with the modules the FMU needs available in this process.
 * binary_path is the file of the FMU's binary (binaries/<platform>/<id>.so); the recorded environment is
 * ../../resources/python_env.txt from there, unless $VIBROFMU_PYTHON_ENV names another file.
 * Returns 0 on success; otherwise 1 with one line (no newline) saying what is missing in message. */
int vibro_python_prepare(const char *binary_path, char *message, size_t size);

#endif
