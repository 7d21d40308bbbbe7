/*
 * Fuzz target: `.poly` text through qk_poly_read() into the dyadic-lattice mode
 * (QK_MESH_DYADIC, real coordinates, edges at multiples of 45 degrees), with an optional
 * size bound and an allocation failure. No crash, no leak, a refusal always with a
 * message, and an accepted input gives a mesh passing the cheap invariant checks of
 * fuzz/fuzz_mesh_check.h. Inputs whose perimeter exceeds 2^12 steps of their finest
 * binary digit are only read (the mesh grows with it).
 */
#include "fuzz/fuzz_mesh_check.h"

int qkf_mesh_dyadic(const uint8_t *data, size_t size) {
  return qkfm_run(data, size, QK_MESH_DYADIC, 64, 4096, 0);
}

#ifndef QKF_REPLAY
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return qkf_mesh_dyadic(data, size); }
#endif
