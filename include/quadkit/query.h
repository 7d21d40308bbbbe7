/**
 * \file query.h
 * \brief The query module.
 */
#ifndef QUADKIT_QUERY_H
#define QUADKIT_QUERY_H

#include "quadkit/index.h"

#endif /* QUADKIT_QUERY_H */
