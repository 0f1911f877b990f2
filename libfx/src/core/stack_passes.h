/* What a stack needs decoded, for the callers that read its input. */
#ifndef LIBFX_CORE_STACK_PASSES_H
#define LIBFX_CORE_STACK_PASSES_H

#include "libfx/fx.h"
#include "core/passes.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Union of the passes the enabled effects and their masks need (Combined always). */
fx_pass_set fx_stack_pass_set(const fx_stack *s);

#ifdef __cplusplus
}
#endif
#endif
