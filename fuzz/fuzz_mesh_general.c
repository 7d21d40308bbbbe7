/*
 * Fuzz target: `.poly` text through qk_poly_read() into the general mode
 * (QK_MESH_GENERAL: any angles, any doubles), small inputs only (at most 24 vertices, extent at
 * most 2^16 times the shortest segment), with an optional size bound and an allocation failure. No
 * crash, no leak, no hang (the mode's work cap answers QK_ERR_LIMIT), a refusal always with a
 * message, and an accepted input gives a mesh passing the cheap invariant checks of
 * fuzz/fuzz_mesh_check.h.
 */
#include "fuzz/fuzz_mesh_check.h"

int qkf_mesh_general(const uint8_t *data, size_t size) {
  return qkfm_run(data, size, QK_MESH_GENERAL, 24, 0, 65536);
}

#ifndef QKF_REPLAY
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  return qkf_mesh_general(data, size);
}
#endif
