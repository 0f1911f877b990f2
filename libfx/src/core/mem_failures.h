/* How many allocations have failed (injected by fx_mem_fail_after or real) since the
 * library was loaded: compare before and after a call that cannot say why it failed
 * (cJSON_Parse returns NULL for bad JSON and for out of memory alike). */
#ifndef LIBFX_MEM_FAILURES_H
#define LIBFX_MEM_FAILURES_H

unsigned long fx_mem_failure_count(void);

#endif
