/* The core layer's small headers in one include, for the effects (effect.h) and the
 * tests. Library files include the headers they use instead. */
#ifndef LIBFX_INTERNAL_H
#define LIBFX_INTERNAL_H

#include "libfx/fx.h"
#include "core/buffers.h"
#include "core/context.h"
#include "core/frame.h"
#include "core/mem.h"
#include "core/passes.h"
#include "core/stack_passes.h"
#include "core/textfile.h"

#endif
