/* Every allocation of the library goes through these, so tests can make the Nth one
 * fail (allocation-failure injection) and check for clean errors without leaks. */
#include "libfx/fx.h"
#include "core/mem.h"
#include "core/mem_failures.h"
#include "core/platform.h"

#include <cjson/cJSON.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static atomic_long fail_countdown; /* 0: never fail */
static atomic_ulong failed_count;  /* allocations that returned NULL, injected or real */

void fx_mem_fail_after(long n)
{
    atomic_store(&fail_countdown, n);
}

static int should_fail(void)
{
    long n = atomic_load(&fail_countdown);
    while (n > 0) {
        if (atomic_compare_exchange_weak(&fail_countdown, &n, n - 1)) {
            if (n == 1)
                atomic_fetch_add(&failed_count, 1);
            return n == 1;
        }
    }
    return 0;
}

static void *counted(void *p)
{
    if (!p)
        atomic_fetch_add(&failed_count, 1);
    return p;
}

unsigned long fx_mem_failure_count(void)
{
    return atomic_load(&failed_count);
}

/* Frame-sized buffers: 2 MiB aligned and marked for transparent huge pages, so the first
 * touch of a 1080p pass costs about 16 page faults instead of 8100 (these machines run
 * THP in madvise mode: plain malloc gets 4 KiB pages). */
#define HUGE_PAGE ((size_t)2 << 20)

static void *alloc_huge(size_t n)
{
    if (n > SIZE_MAX - HUGE_PAGE)
        return counted(NULL);
    size_t rounded = (n + HUGE_PAGE - 1) & ~(HUGE_PAGE - 1);
    return counted(fx_os_alloc_pages(rounded, HUGE_PAGE));
}

/* n bytes, from huge_from up as whole advised huge pages */
static void *alloc_from(size_t n, size_t huge_from)
{
    if (should_fail())
        return NULL;
    if (n >= huge_from)
        return alloc_huge(n);
    return counted(malloc(n ? n : 1));
}

void *fx_mem_alloc(size_t n)
{
    return alloc_from(n, HUGE_PAGE);
}

void *fx_mem_alloc_whole(size_t n)
{
    return alloc_from(n, (size_t)256 << 10);
}

void *fx_mem_calloc(size_t count, size_t size)
{
    if (should_fail())
        return NULL;
    return counted(calloc(count ? count : 1, size ? size : 1));
}

void *fx_mem_realloc(void *p, size_t n)
{
    if (should_fail())
        return NULL;
    return counted(realloc(p, n ? n : 1));
}

/* cJSON allocates through fx_mem too (recipes, sidecars, masks, presets), so failure
 * injection covers the JSON parsers and callers can tell "out of memory" from "bad JSON"
 * (fx_mem_failure_count). Installed when the library is loaded: cJSON's hooks are global
 * and plain malloc/free underneath, so other cJSON users in the process are unaffected. */
static void *cjson_alloc(size_t n)
{
    return fx_mem_alloc(n);
}

__attribute__((constructor)) static void fx_mem_hook_cjson(void)
{
    cJSON_Hooks hooks = {cjson_alloc, fx_mem_free};
    cJSON_InitHooks(&hooks);
}

void fx_mem_free(void *p)
{
    free(p);
}

char *fx_mem_strdup(const char *s)
{
    if (!s)
        return NULL;
    size_t n = strlen(s) + 1;
    char *d = fx_mem_alloc(n);
    if (d)
        memcpy(d, s, n);
    return d;
}

int fx_size_mul(size_t *out, size_t a, size_t b, size_t c)
{
    size_t ab;
    if (__builtin_mul_overflow(a, b, &ab) || __builtin_mul_overflow(ab, c, out))
        return 0;
    return 1;
}

char *fx_json_strdup(const char *s)
{
    return fx_mem_strdup(s);
}

void fx_free(void *p)
{
    fx_mem_free(p);
}
