/* Memory: every allocation of the library goes through here, so tests can make the Nth
 * one fail and prove each caller cleans up and reports it. */
#ifndef LIBFX_CORE_MEM_H
#define LIBFX_CORE_MEM_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Blocks of 2 MiB and more come huge-page aligned and advised (fewer first-touch faults). */
void *fx_mem_alloc(size_t n);
/* A buffer written whole as soon as it is allocated (the workers' scratch rows): from
 * 256 KiB it takes whole advised huge pages, so a process's first frame pays one page fault
 * per 2 MiB instead of 512; below that, as fx_mem_alloc. Freed with fx_mem_free. */
void *fx_mem_alloc_whole(size_t n);
void *fx_mem_calloc(size_t count, size_t size);
void *fx_mem_realloc(void *p, size_t n);
void fx_mem_free(void *p);
char *fx_mem_strdup(const char *s);
/* Test hook: the Nth allocation from now fails (0 disables). Not exported from the .so. */
void fx_mem_fail_after(long n);
/* a * b * c with overflow check; returns 0 and leaves *out untouched on overflow. */
int fx_size_mul(size_t *out, size_t a, size_t b, size_t c);
/* A copy of a JSON string in fx_mem memory, for the caller to release with fx_free. */
char *fx_json_strdup(const char *s);

#ifdef __cplusplus
}
#endif
#endif
