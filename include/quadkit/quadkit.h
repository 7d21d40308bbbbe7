/**
 * \file quadkit.h
 * \brief Umbrella header: includes every quadkit module.
 */
#ifndef QUADKIT_QUADKIT_H
#define QUADKIT_QUADKIT_H

#include "quadkit/collide.h"
#include "quadkit/common.h"
#include "quadkit/index.h"
#include "quadkit/io.h"
#include "quadkit/mesh.h"
#include "quadkit/query.h"
#include "quadkit/region.h"

#endif /* QUADKIT_QUADKIT_H */
