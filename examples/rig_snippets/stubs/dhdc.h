/* The Force Dimension SDK calls examples/rig_snippets/force_dimension_loop.c
 * uses (their signatures in dhdc.h), so CI compiles it without the SDK. */
#pragma once
int dhdKbHit(void);
int dhdGetPosition(double *px, double *py, double *pz);
int dhdSetForce(double fx, double fy, double fz);
