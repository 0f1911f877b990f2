/* bench_fresh_pages: what one frame-sized buffer costs the first time a process touches it.
 *
 *   bench_fresh_pages [W H]     (default 1920 1080)
 *
 * Allocates a W x H RGBA float buffer the way libfx does (fx_mem_alloc: 2 MiB aligned,
 * MADV_HUGEPAGE) in this fresh process and times filling it once (page faults: the kernel
 * zeroes every page, the hypervisor may back it), then again (memory already mapped).
 * Prints "first_ms second_ms". The difference is the floor of what any effect that needs
 * a second frame-sized buffer pays on the first frame of a process. */
#include "core/internal.h"

#include "bench_util.h"

#include <stdio.h>
#include <string.h>

int main(int argc, char **argv)
{
    int w = argc > 2 ? atoi(argv[1]) : 1920, h = argc > 2 ? atoi(argv[2]) : 1080;
    size_t bytes = (size_t)w * h * 4 * sizeof(float);
    float *p = fx_mem_alloc(bytes);
    if (!p) {
        fprintf(stderr, "bench_fresh_pages: out of memory for %zu bytes\n", bytes);
        return 1;
    }
    double t0 = now_ms();
    memset(p, 1, bytes);
    double t1 = now_ms();
    memset(p, 2, bytes);
    double t2 = now_ms();
    printf("%.3f %.3f\n", t1 - t0, t2 - t1);
    fx_mem_free(p);
    return 0;
}
