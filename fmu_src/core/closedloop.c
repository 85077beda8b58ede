/*
 * closedloop.c -- the closed loop of closedloop.h.
 */
#include "closedloop.h"
