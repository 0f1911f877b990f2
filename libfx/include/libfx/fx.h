/*
 * libfx: real-time-style render effects over Blender's multilayer EXR passes.
 *
 * The one public header. Conventions (docs/api.md has the long form):
 *  - Every fallible call returns fx_result; FX_OK is 0. The message of the
 *    last failure is per context and per calling thread: fx_context_error().
 *    The library never prints, exits or aborts.
 *  - Opaque objects come in _new/_free pairs; _free(NULL) is a no-op. Whoever
 *    allocates frees. Pointers returned by getters are borrowed views, valid
 *    until the owning object is freed or changed.
 *  - Strings the library allocates for you (char **out) are freed with fx_free().
 *  - Structs that cross the ABI start with `size_t size` (set it to sizeof).
 *  - No varargs: every function can be bound from ctypes.
 *  - Threads: an object is used by one thread at a time; the library runs its
 *    own parallel loops and its output is bit-identical for any thread count.
 *  - Matrices are float[16], row-major, column-vector convention (p' = M p),
 *    i.e. exactly Blender's Matrix rows.
 */
#ifndef LIBFX_FX_H
#define LIBFX_FX_H

#include <stddef.h>
#include <stdint.h>

#if defined(_WIN32)
#  if defined(FX_BUILDING_LIBRARY)
#    define FX_API __declspec(dllexport)
#  else
#    define FX_API
#  endif
#elif defined(__GNUC__) && __GNUC__ >= 4
#  define FX_API __attribute__((visibility("default")))
#else
#  define FX_API
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* Bumped on every ABI break, together with the library's SOVERSION. */
#define FX_ABI_VERSION 2

typedef enum fx_result {
    FX_OK = 0,
    FX_ERR_INVALID_ARGUMENT = 1, /* NULL pointer, wrong struct size, index out of range */
    FX_ERR_OUT_OF_MEMORY = 2,
    FX_ERR_IO = 3,               /* a file cannot be opened, read, written or renamed */
    FX_ERR_BAD_FILE = 4,         /* not an EXR, damaged, truncated, or unsupported (deep) */
    FX_ERR_LIMIT = 5,            /* over the image-size limits or the memory budget */
    FX_ERR_MISSING_PASS = 6,     /* a pass an effect or a mask needs is not in the frame */
    FX_ERR_UNKNOWN_EFFECT = 7,
    FX_ERR_BAD_PARAM = 8,        /* unknown parameter, wrong type, out of range */
    FX_ERR_BAD_RECIPE = 9,       /* malformed JSON, or JSON that is not a recipe/mask/camera */
    FX_ERR_NO_CAMERA = 10,       /* an effect needs camera matrices and the frame has none */
    FX_ERR_CANCELLED = 11,       /* the progress callback asked to stop */
    FX_ERR_INTERNAL = 12,
    /* Appended after 0.1.0 (the values above never change): */
    FX_ERR_NO_AUX_VIEW = 13,     /* an effect needs an auxiliary view (light depth view, rain map)
                                    the frame does not list (fx_stack_required_aux_views) */
    FX_ERR_NO_LIGHTS = 14        /* an effect needs the scene's lights and the frame has none
                                    (they come with the scene sidecar) */
} fx_result;

typedef struct fx_context fx_context; /* threads, limits, per-thread last error, warnings */
typedef struct fx_frame fx_frame;     /* named float passes + windows + camera + metadata */
typedef struct fx_stack fx_stack;     /* ordered effects with validated parameters and masks */

/* ---- Library ------------------------------------------------------------ */

FX_API int fx_abi_version(void);            /* == FX_ABI_VERSION of the built library */
FX_API const char *fx_version_string(void); /* "0.1.0" */
FX_API const char *fx_result_name(fx_result r); /* "FX_ERR_BAD_FILE" */
FX_API void fx_free(void *p);               /* frees strings the library returned */

/* ---- Context ------------------------------------------------------------ */

/* threads <= 0: one per available core. */
FX_API fx_result fx_context_new(fx_context **out, int threads);
FX_API void fx_context_free(fx_context *ctx);
FX_API int fx_context_threads(const fx_context *ctx);
/* Message of the last failed call made on this context by the calling thread; "" if none. */
FX_API const char *fx_context_error(const fx_context *ctx);
/* Warnings collected by calls on this context (lossy DWA data, non-finite values replaced...). */
FX_API int fx_context_warning_count(const fx_context *ctx);
FX_API const char *fx_context_warning(const fx_context *ctx, int index);
FX_API void fx_context_clear_warnings(fx_context *ctx);
/* Largest width/height accepted from a file, and the byte budget for pixel buffers. */
FX_API fx_result fx_context_set_limits(fx_context *ctx, int max_width, int max_height,
                                       uint64_t max_bytes);
/* Progress of long work: stage is a short label, fraction in [0,1]. Return non-zero to cancel.
 * Called on the thread that called into the library. */
typedef int (*fx_progress_fn)(void *user, const char *stage, double fraction);
FX_API void fx_context_set_progress(fx_context *ctx, fx_progress_fn fn, void *user);

/* ---- Effect introspection ------------------------------------------------ */

typedef enum fx_param_type {
    FX_PARAM_FLOAT = 0,
    FX_PARAM_INT = 1,
    FX_PARAM_BOOL = 2,
    FX_PARAM_ENUM = 3,   /* one of enum_items; default_value is the index */
    FX_PARAM_FLOATS = 4, /* fixed-length float vector: colour, position, matrix */
    FX_PARAM_STRING = 5
} fx_param_type;

typedef struct fx_param_info {
    size_t size;               /* sizeof(fx_param_info) of the library */
    const char *name;
    const char *doc;
    fx_param_type type;
    const char *hint;          /* UI hint: "", "pixels", "color", "matrix4", "angle", "factor", "path",
                                  "texels". "pixels": a length in frame pixels, divided by the proxy
                                  factor when the stack runs on a proxy (fx_frame_reduce); "texels":
                                  a length in pixels of another raster (a light map, a pyramid
                                  level, a 720-line reference image), never scaled; "mask" (a
                                  STRING): a mask JSON object as a recipe entry's "mask" takes,
                                  checked when set, its rectangle scaled on proxies */
    double default_value;      /* FLOAT, INT, BOOL, ENUM (index) */
    double min, max;           /* hard range: values outside are errors */
    double soft_min, soft_max; /* the useful range, for sliders */
    int count;                 /* FLOATS: number of floats; else 1 */
    const float *default_floats;
    const char *const *enum_items;
    int enum_count;
    const char *default_string;
} fx_param_info;

typedef enum fx_quality {
    FX_QUALITY_DRAFT = 0,
    FX_QUALITY_PREVIEW = 1,
    FX_QUALITY_FINAL = 2,
    FX_QUALITY_REFERENCE = 3 /* slow, converged: what errors are measured against */
} fx_quality;

FX_API int fx_effect_count(void);
FX_API const char *fx_effect_name(int index);             /* NULL if out of range */
FX_API const char *fx_effect_doc(const char *effect);     /* one line; NULL if unknown */
FX_API int fx_effect_param_count(const char *effect);     /* -1 if unknown */
FX_API const fx_param_info *fx_effect_param(const char *effect, int index);
/* Everything about an effect as JSON: doc, params (with ranges, defaults, enum items),
 * quality presets, halo, the passes it needs with default parameters. */
FX_API fx_result fx_effect_describe_json(fx_context *ctx, const char *effect, char **out_json);
/* "draft", "preview", "final", "reference" <-> fx_quality; -1 if unknown. */
FX_API int fx_quality_from_name(const char *name);
FX_API const char *fx_quality_name(int quality);

/* ---- Camera ------------------------------------------------------------- */

typedef struct fx_camera {
    size_t size;               /* sizeof(fx_camera) */
    float world_to_camera[16]; /* Blender: camera.matrix_world.inverted() */
    float projection[16];      /* Blender: camera.calc_matrix_camera(depsgraph, x, y), OpenGL clip space */
    float clip_start, clip_end;
    int orthographic;
} fx_camera;

/* A camera as JSON, as the scene sidecar holds it: {"world_to_camera": [[4],[4],[4],[4]],
 * "projection": [...], "clip_start": f, "clip_end": f}. Matrices as rows. */
FX_API fx_result fx_camera_from_json(fx_context *ctx, const char *json, fx_camera *out);

/* ---- Frames ------------------------------------------------------------- */
/* (fx_frame_apply_sidecar, below the frame functions, applies a whole scene sidecar.) */

/* A frame holds planes of float pixels named by canonical pass names
 * ("Combined" RGBA, "Depth", "Normal" XYZ, "Position", "IndexOB", "IndexMA",
 * "DiffDir", ..., "CryptoObject00" ...). Pixels are interleaved, rows top to
 * bottom, width x height = the EXR data window. */
FX_API fx_result fx_frame_new(fx_context *ctx, int width, int height, fx_frame **out);
FX_API void fx_frame_free(fx_frame *f);
FX_API int fx_frame_width(const fx_frame *f);
FX_API int fx_frame_height(const fx_frame *f);
/* Windows as EXR boxes {xmin, ymin, xmax, ymax}, inclusive. A new frame has both
 * at {0, 0, w-1, h-1}; the data window must be w x h. */
FX_API fx_result fx_frame_set_windows(fx_frame *f, const int data_window[4], const int display_window[4]);
FX_API void fx_frame_windows(const fx_frame *f, int data_window[4], int display_window[4]);
/* Adds (or replaces) a pass; data is copied (NULL: zeros). channels 1..4. */
FX_API fx_result fx_frame_add_pass(fx_frame *f, const char *name, int channels, const float *data);
/* Borrowed pointer to a pass's pixels, writable; FX_ERR_MISSING_PASS if absent.
 * Frames share unchanged pixels, in one context or across contexts (an empty stack's
 * output holds its input's Combined; fx_frame_copy_passes shares): a pass asked for here
 * gets its own copy first if another frame holds it, and is never shared from then on. */
FX_API fx_result fx_frame_pass(const fx_frame *f, const char *name, float **data, int *channels);
/* Read-only pointer to a pass's pixels, never copied; valid until f is freed or the
 * pass replaced. Prefer it to fx_frame_pass for reading. */
FX_API fx_result fx_frame_pass_read(const fx_frame *f, const char *name, const float **data, int *channels);
FX_API int fx_frame_pass_count(const fx_frame *f);
FX_API const char *fx_frame_pass_name(const fx_frame *f, int index);
FX_API int fx_frame_pass_channels(const fx_frame *f, int index);
FX_API fx_result fx_frame_set_camera(fx_frame *f, const fx_camera *camera);
/* Returns 1 and fills *out if the frame has a camera, else 0. */
FX_API int fx_frame_camera(const fx_frame *f, fx_camera *out);
/* Scene time, for animated effects: frame number and frames per second. */
FX_API void fx_frame_set_time(fx_frame *f, double frame, double fps);
FX_API void fx_frame_time(const fx_frame *f, double *frame, double *fps);
/* Scene sidecar JSON, what Blender's EXRs lack: the camera (as fx_camera_from_json),
 * and optionally "lights": [{"name": "Sun", "type": "SUN"|"POINT"|"SPOT"|"AREA",
 * "position": [x,y,z], "direction": [x,y,z] (world, the way the light travels),
 * "color": [r,g,b], "energy": f, "angle": f}] and "frame", "fps". The camera is set,
 * the lights are kept as the frame's "libfx:lights" metadata (a JSON array, written to
 * and read from EXR headers), the time is set. Keys other than these are errors. */
FX_API fx_result fx_frame_apply_sidecar(fx_frame *f, const char *json);
FX_API fx_result fx_frame_apply_sidecar_file(fx_frame *f, const char *path);
/* String metadata (e.g. "cryptomatte/CryptoObject/manifest"); NULL value removes. */
FX_API fx_result fx_frame_set_meta(fx_frame *f, const char *key, const char *value);
FX_API const char *fx_frame_meta(const fx_frame *f, const char *key); /* NULL if absent */

typedef struct fx_read_options {
    size_t size;           /* sizeof(fx_read_options) */
    const char *layer;     /* view layer to read; NULL: the only one (error if several) */
    const char *view;      /* stereo view; NULL: the default view */
    const fx_stack *stack; /* decode only the passes this stack needs; NULL: decode all passes */
} fx_read_options;

/* Reads a Blender (or any) EXR. opts may be NULL (all passes, default layer/view).
 * Non-finite values are replaced (NaN -> 0, +-Inf -> +-FLT_MAX) and counted in a warning. */
FX_API fx_result fx_frame_read_exr(fx_context *ctx, const char *path,
                                   const fx_read_options *opts, fx_frame **out);
/* Header summary of an EXR as JSON (size, windows, parts, layers, views, passes with
 * channel types, compression, camera present, Cryptomatte names). Decodes no pixels. */
FX_API fx_result fx_exr_info_json(fx_context *ctx, const char *path, char **out_json);

typedef struct fx_write_options {
    size_t size;            /* sizeof(fx_write_options) */
    int half_color;         /* 1: colour passes as half; data passes always float */
    int only_combined;      /* 1: write Combined only; 0: every pass in the frame */
    const char *input_path; /* refuse to write over this file (the input) */
    /* Appended after 0.1.0 (a smaller `size` is accepted and means the default):
     * "zip" (default, deflate level 1 through libdeflate when built with it, else OpenEXR's
     * zlib: fast, a few % larger than level 6), "zip:1".."zip:9",
     * "zips", "zips:N", "piz", "rle", "none"; NULL: the default. Lossless only. */
    const char *compression;
} fx_write_options;

/* Writes a multilayer EXR atomically (temporary file in the same folder + rename),
 * with worldToCamera/worldToNDC attributes when the frame has a camera. */
FX_API fx_result fx_frame_write_exr(const fx_frame *f, const char *path, const fx_write_options *opts);
/* 8-bit sRGB PNG preview of a pass (NULL: Combined), exposure in stops. Atomic. */
FX_API fx_result fx_frame_write_png(const fx_frame *f, const char *path, const char *pass, float exposure);

/* ---- Proxy resolutions (interactive previews) ------------------------------ */

/* A proxy of `in` at 1/factor resolution, factor 1..16 (1: a copy sharing in's pixels):
 * ceil(w/factor) x ceil(h/factor) pixels, windows scaled to match (the camera then maps
 * world points to the right proxy pixels), camera, time, metadata and aux views kept.
 * Each proxy pixel stands for a factor x factor block of in (edge blocks: the part inside
 * the frame). Colour and light passes (Combined, Alpha, Diff*, Gloss*, Trans*, Emit, Env,
 * AO, Shadow, Volume*) are the mean of the block's finite values; every other pass
 * (IndexOB, IndexMA, Crypto*, Depth, Mist, Normal, Position, Vector, UV, unknown names)
 * takes all its values from one pixel of the block, the same for every such pass: the one
 * nearest the block's centre. IDs are never mixed. The stack run on a proxy divides every
 * parameter whose hint is "pixels" by the factor, and mask rectangles too, so that the
 * proxy looks like the full frame. Reducing a proxy multiplies the factors. */
FX_API fx_result fx_frame_reduce(const fx_frame *in, int factor, fx_frame **out);
/* 1 for a full frame; the factor of fx_frame_reduce for a proxy and for the output of a
 * stack run on a proxy. 0 for NULL. */
FX_API int fx_frame_proxy_factor(const fx_frame *f);
/* Fills rgba (width * height * 4 floats, the caller's) from a pass (NULL: "Combined"):
 * 4 channels as they are, 3 with alpha 1, 1 as grey with alpha 1 (2: the two, 0, 1).
 * Another size than the frame's is resampled, pixel centres aligned: bilinear for colour
 * passes, nearest for the others (IDs are not mixed). bottom_up = 1 writes rows bottom to
 * top (Blender's Image.pixels). Values are finite (NaN -> 0, +-Inf -> +-FLT_MAX). */
FX_API fx_result fx_frame_read_pixels(const fx_frame *f, const char *pass, int width, int height,
                                      int bottom_up, float *rgba);

/* ---- Stacks and recipes -------------------------------------------------- */

FX_API fx_result fx_stack_new(fx_context *ctx, fx_stack **out);
FX_API void fx_stack_free(fx_stack *s);
/* Recipe JSON (docs/recipes.md):
 * {"version": 1, "quality": "final", "effects": [{"effect": "pixelate", "enabled": true,
 *   "quality": "draft", "params": {...}, "mask": {"object": "Statue", "invert": false}}]}
 * Replaces the stack's content; on error the stack is unchanged and the message names
 * the effect (by position and name), the parameter and the allowed range. */
FX_API fx_result fx_stack_load_json(fx_stack *s, const char *json);
FX_API fx_result fx_stack_load_file(fx_stack *s, const char *path);
FX_API fx_result fx_stack_to_json(const fx_stack *s, char **out_json);
FX_API int fx_stack_count(const fx_stack *s);
FX_API const char *fx_stack_effect(const fx_stack *s, int index); /* effect name */
FX_API fx_result fx_stack_append(fx_stack *s, const char *effect, int *out_index);
FX_API fx_result fx_stack_remove(fx_stack *s, int index);
FX_API fx_result fx_stack_set_enabled(fx_stack *s, int index, int enabled);
/* Setting a parameter marks it explicit: quality presets no longer change it. Each
 * setter checks the value's type and range and then the whole effect with it (defaults,
 * preset and explicit values, the effect's checks between parameters): a bad value is
 * refused with a message naming the effect and the parameter, and the stack is left
 * unchanged. A stack that was built without an error runs without a parameter error. */
FX_API fx_result fx_stack_set_float(fx_stack *s, int index, const char *param, double value);
FX_API fx_result fx_stack_set_int(fx_stack *s, int index, const char *param, int value);
FX_API fx_result fx_stack_set_enum(fx_stack *s, int index, const char *param, const char *item);
FX_API fx_result fx_stack_set_floats(fx_stack *s, int index, const char *param, const float *values, int count);
FX_API fx_result fx_stack_set_string(fx_stack *s, int index, const char *param, const char *value);
/* Mask JSON: {"material": "Name"|[...], "object": ..., "material_index": n|[...],
 * "object_index": ..., "rect": [x, y, w, h] (pixels), "rect_relative": [x, y, w, h] (fractions
 * of the display window), "invert": bool}; "{}" or NULL: everything. */
FX_API fx_result fx_stack_set_mask_json(fx_stack *s, int index, const char *mask_json);
/* The stack's quality (default final); an effect's own comes from its recipe entry.
 * Every effect that follows the stack's quality is checked with the new preset: on a
 * clash with an explicit value the call fails and the stack is unchanged. */
FX_API fx_result fx_stack_set_quality(fx_stack *s, int quality);
/* What the enabled effects and their masks need: {"passes": ["Combined", "CryptoObject",
 * ...], "camera": bool}. Cryptomatte is named by type (CryptoObject/CryptoMaterial/CryptoAsset). */
FX_API fx_result fx_stack_required_passes(const fx_stack *s, char **out_json);
/* Debug outputs (hit masks, ray lengths, mattes...) added to the output frame as
 * "fx<effect index>_<effect>_<name>" passes (e.g. "fx2_pixelate_cells"). Off by default. */
FX_API void fx_stack_set_debug_outputs(fx_stack *s, int enabled);
/* Runs the enabled effects in order on `in` (never modified) and returns a new frame
 * with the result as "Combined", plus the debug passes when enabled. The output has
 * in's windows, camera, time and metadata; other passes are not copied (see
 * fx_frame_copy_passes). The output belongs to the stack's context, which may differ
 * from in's (a reader context and one per render thread): its buffers go back to the
 * stack's context when it is freed, and it outlives in and in's context. */
FX_API fx_result fx_stack_run(fx_stack *s, const fx_frame *in, fx_frame **out);
/* fx_stack_run for a caller done with `in` (a one-frame command, a render handler): the
 * stack may write the result over in's Combined, so effects that can work in place (per-
 * pixel ones, the blur) need no second frame-sized buffer (in a fresh process, no fresh
 * pages). keep_passes: the output also holds in's other passes (handed over, not copied).
 * `in` is freed in any case. */
FX_API fx_result fx_stack_run_consume(fx_stack *s, fx_frame *in, int keep_passes, fx_frame **out);
/* Per-effect wall time of the last run: [{"index": 0, "effect": "pixelate", "ms": 1.2}, ...] */
FX_API fx_result fx_stack_timings_json(const fx_stack *s, char **out_json);
/* Gives dst every pass of src that dst does not have (to keep input passes in an
 * output): shared, not copied (the frames may be of two contexts). */
FX_API fx_result fx_frame_copy_passes(fx_frame *dst, const fx_frame *src);

/* ---- Auxiliary views (shadows and rain) -----------------------------------
 * Extra depth renders of the scene from another viewpoint, each an EXR with a Depth
 * pass (planar depth along the view's -Z) plus its camera: "light:<light name>" (the
 * light's shadow view: orthographic for a sun, perspective for a spot) and "rain_map"
 * (a top-down orthographic view over the rain area). The scene sidecar lists them as
 * "aux_views": [{"name": "light:Sun", "path": "/abs/light.exr", "world_to_camera": [...],
 * "projection": [...], "clip_start": f, "clip_end": f, "orthographic": bool}]; they are
 * kept as the frame's "libfx/aux_views" metadata (written to and read from EXR headers)
 * and effects load them when they run. */
/* Adds (or replaces, by name) one aux view of the frame. */
FX_API fx_result fx_frame_set_aux_view(fx_frame *f, const char *name, const char *exr_path,
                                       const fx_camera *camera);
/* The aux views the enabled effects need: {"aux_views": [{"name": "light:Sun", "kind":
 * "light", "light": "Sun"}, {"name": "rain_map", "kind": "rain_map"}]}. A light name ""
 * ("light:") means the scene's first sun. Renderers make only these. */
FX_API fx_result fx_stack_required_aux_views(const fx_stack *s, char **out_json);
/* Built aux-view maps (a light view's filtered moments, the rain map) are kept per context
 * and reused while the view's sidecar entry, file size and modification time and the
 * effect's build parameters are the same, so frames 2..N of a batch neither re-read nor
 * rebuild them. max_bytes bounds the cache (default 768 MiB, never above the context's
 * memory limit); 0 turns it off. Results are bit-identical either way. */
FX_API fx_result fx_context_set_aux_cache(fx_context *c, uint64_t max_bytes);

/* ---- Effect parameter versions ---------------------------------------------
 * Each effect's parameter table has a version (1 until a parameter is renamed or
 * re-ranged). A recipe entry may say which version its "params" were written at:
 * {"effect": "pixelate", "params_version": 1, "params": {...}} (absent: 1). Loading an
 * older version migrates it (renamed parameters moved to their new names, re-ranged
 * values converted) with one context warning per migrated parameter; nothing is dropped
 * (a parameter the migration does not know stays and fails as unknown). A version newer
 * than the library's is refused. fx_stack_to_json writes every entry's current version. */
/* The current params_version of an effect (1 for an effect that never changed). */
FX_API fx_result fx_effect_params_version(fx_context *ctx, const char *effect, int *out);
/* Migrates a JSON object of one effect's parameters written at from_version to the
 * current version; *out_json is a new JSON object (fx_free). from_version equal to the
 * current one returns the object unchanged; newer is FX_ERR_BAD_RECIPE. */
FX_API fx_result fx_effect_migrate_params(fx_context *ctx, const char *effect, int from_version,
                                          const char *params_json, char **out_json);
/* The parameters the effect at `index` runs with (defaults, then its quality preset, then
 * the explicit values), every parameter of its table, as a JSON object (fx_free). */
FX_API fx_result fx_stack_effective_params_json(const fx_stack *s, int index, char **out_json);

#ifdef __cplusplus
}
#endif
#endif /* LIBFX_FX_H */
