/* A pixel rectangle: the bounds of a mask, the region an effect computes. */
#ifndef LIBFX_CORE_RECT_H
#define LIBFX_CORE_RECT_H

typedef struct fx_rect {
    int x0, y0, x1, y1; /* half-open: x0 <= x < x1, in frame pixels (data window) */
} fx_rect;

#endif
