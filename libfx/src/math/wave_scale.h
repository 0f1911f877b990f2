/* The dominant wavelength of a water surface from its normals (voronoi_caustics'
 * cell_scale auto). */
#ifndef FX_MATH_WAVE_SCALE_H
#define FX_MATH_WAVE_SCALE_H

/* Rice's mean wavelength of the surface's slope field s = (-nx / nz, -ny / nz) (world
 * normals, z up): lambda = 2 pi sqrt(m0 / m2), m0 the slope's variance, m2 the mean squared
 * derivative of the slope along the grid's two axes (finite differences over neighbouring
 * valid samples, each divided by the world distance between them in the horizontal plane).
 * Exact for one sinusoidal wave of any direction on a grid whose axes are orthogonal in
 * the plane (up to the finite difference: 2 sin(k l / 2) / l for k); for a spectrum, its
 * mean wavelength weighted by the slope's power. normal: w x h samples of nc >= 3 floats;
 * xy: 2 floats per sample (world x, y); valid: nonzero where the sample is water (NULL:
 * all). Returns 0 and sets *lambda, or -1 when nothing can be estimated (fewer than 16 valid
 * pairs, a flat surface, non-finite data). Deterministic (one fixed order of sums). */
int fx_wave_length(const float *normal, int nc, const float *xy, const unsigned char *valid, int w, int h,
                   double *lambda);

#endif
