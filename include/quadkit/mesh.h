/**
 * \file mesh.h
 * \brief The mesh module.
 */
#ifndef QUADKIT_MESH_H
#define QUADKIT_MESH_H

#include "quadkit/index.h"

#endif /* QUADKIT_MESH_H */
