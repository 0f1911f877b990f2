/* {effect, bound at 1/2, bound at 1/4}: MAE of RGB clipped to [0, 1], draft on the proxy vs final
 * reduced the same way, on test_proxy's synthetic 192x128 scene. Measured (LIBFX_PROXY_PRINT=1)
 * and given 1.5x and 0.001 of margin. Lines of 1-2 proxy pixels come out up to twice as wide
 * as on the full frame (the edge operators draw 2 pixels at least), hence cel_shading's and
 * edges' bounds at 1/2; under a proxy pixel they are drawn lighter (edges.c proxy_adjust). */
{"bloom", 0.012, 0.007}, /* measured 0.00673, 0.00354 */
{"cel_shading", 0.034, 0.011}, /* measured 0.02144, 0.00616 (under a proxy pixel: lighter, edges.c proxy_adjust) */
{"color_matrix", 0.001, 0.001}, /* measured 0.00000, 0.00000 */
{"edges", 0.024, 0.005}, /* measured 0.01488, 0.00253 (under a proxy pixel: lighter; depth threshold x f) */
{"gaussian_blur", 0.002, 0.002}, /* measured 0.00045, 0.00066 */
{"god_rays", 0.005, 0.010}, /* measured 0.00256, 0.00593 */
{"pixelate", 0.003, 0.005}, /* measured 0.00071, 0.00232 */
{"posterize", 0.003, 0.005}, /* measured 0.00104, 0.00256 */
{"rain", 0.002, 0.002}, /* measured 0.00047, 0.00042 (draft downsample 16) */
{"rain_splashes", 0.004, 0.004}, /* measured 0.00147, 0.00188 */
{"sin_city", 0.001, 0.001}, /* measured 0.00000, 0.00000 */
{"ssr_mirror", 0.0035, 0.0068}, /* measured 0.00169, 0.00388 (draft without retrace_edges: 4x4 cells; before 0.00086, 0.00118) */
{"voronoi_caustics", 0.103, 0.092}, /* measured 0.06786, 0.06042 */
{"vsm_shadows", 0.009, 0.009}, /* measured 0.00468, 0.00469 */
{"wet_surfaces", 0.006, 0.006}, /* measured 0.00313, 0.00327 (draft downsample 3) */
