/* The per-context buffer store (core/buffers.h): exact sizes come back, fx_buffer_get_at_least
 * takes an exact one first, else the smallest held one up to 4x as big and says its size,
 * small requests and failed allocations fall through cleanly. */
#include "testutil.h"

#include "core/buffers.h"
#include "core/mem.h"

#include <string.h>

#define MIB ((size_t)1 << 20)

int main(void)
{
    fx_context *ctx = NULL;
    fx_context_new(&ctx, 1);
    size_t cap = 0;
    unsigned char *a = fx_buffer_get(ctx, 4 * MIB), *x = fx_buffer_get(ctx, 3 * MIB);
    CHECK(a && x);
    memset(a, 1, 4 * MIB);
    memset(x, 2, 3 * MIB);
    fx_buffer_put(ctx, a, 4 * MIB);
    fx_buffer_put(ctx, x, 3 * MIB);
    /* exact only: a 2 MiB request does not take the 3 or 4 MiB ones */
    unsigned char *f = fx_buffer_get(ctx, 2 * MIB);
    CHECK(f && f != a && f != x);
    fx_buffer_put(ctx, f, 2 * MIB); /* now held: 4, 3, 2 MiB */
    /* exact first, then the smallest that fits within 4x */
    unsigned char *b = fx_buffer_get_at_least(ctx, 3 * MIB, &cap);
    CHECK(b == x && cap == 3 * MIB);
    unsigned char *c = fx_buffer_get_at_least(ctx, 2 * MIB + 1, &cap);
    CHECK(c == a && cap == 4 * MIB && c[4 * MIB - 1] == 1); /* the whole 4 MiB is usable */
    fx_buffer_put(ctx, b, 3 * MIB);
    fx_buffer_put(ctx, c, cap);
    /* 1 MiB: the 2 MiB one (smallest within 4x) */
    unsigned char *d = fx_buffer_get_at_least(ctx, MIB, &cap);
    CHECK(d == f && cap == 2 * MIB);
    fx_buffer_put(ctx, d, cap);
    /* the smallest that fits: held 4 and 3 MiB (the 2 MiB one taken out), asked 1.5 MiB */
    unsigned char *t = fx_buffer_get(ctx, 2 * MIB);
    CHECK(t == f);
    unsigned char *e = fx_buffer_get_at_least(ctx, MIB + MIB / 2, &cap);
    CHECK(e == x && cap == 3 * MIB);
    fx_buffer_put(ctx, e, cap);
    fx_buffer_put(ctx, t, 2 * MIB);
    /* below the store's minimum: plain memory of the size asked */
    unsigned char *s = fx_buffer_get_at_least(ctx, 256 << 10, &cap);
    CHECK(s && s != a && s != x && s != f && cap == (size_t)256 << 10);
    fx_buffer_put(ctx, s, cap);
    /* nothing held fits (16 MiB > 4 MiB): new memory; and its failure gives NULL, capacity 0 */
    fx_mem_fail_after(1);
    unsigned char *g = fx_buffer_get_at_least(ctx, 16 * MIB, &cap);
    CHECK(!g && cap == 0);
    fx_mem_fail_after(0);
    g = fx_buffer_get_at_least(ctx, 16 * MIB, &cap);
    CHECK(g && cap == 16 * MIB && g != a && g != x && g != f);
    fx_buffer_put(ctx, g, cap);
    /* more than 4x as big is not taken: a context holding only 16 MiB, asked 2 MiB */
    fx_context *c2 = NULL;
    fx_context_new(&c2, 1);
    unsigned char *h = fx_buffer_get(c2, 16 * MIB);
    fx_buffer_put(c2, h, 16 * MIB);
    unsigned char *k = fx_buffer_get_at_least(c2, 2 * MIB, &cap);
    CHECK(k && k != h && cap == 2 * MIB);
    fx_buffer_put(c2, k, cap);
    k = fx_buffer_get_at_least(c2, 4 * MIB, &cap);
    CHECK(k == h && cap == 16 * MIB);
    fx_buffer_put(c2, k, cap);
    fx_context_free(c2);
    /* a NULL context: plain memory */
    unsigned char *n = fx_buffer_get_at_least(NULL, 2 * MIB, &cap);
    CHECK(n && cap == 2 * MIB);
    fx_buffer_put(NULL, n, cap);
    fx_context_free(ctx);
    return tu_finish("test_buffers");
}
