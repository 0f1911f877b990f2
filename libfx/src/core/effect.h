/* The effect class: every effect is one file defining one `const fx_effect_class`.
 *
 * An effect declares its parameters once, as a table beside its params struct
 * (name, type, default, hard and soft range, doc, offset into the struct). The
 * recipe parser, the C setters, `libfx describe`, the add-on's UI and the docs all
 * read that table. The stack hands process() the effective parameters (defaults,
 * then the quality preset, then the user's explicit values), already checked.
 *
 * ---- Adding an effect: the checklist ----
 * Files to add:
 *  - libfx/src/effects/foo.c defining `const fx_effect_class fx_effect_foo` (the registry
 *    is generated from the file names: nothing to list anywhere; every .c file there is
 *    an effect, so shared code goes in math/ or a header-only helper);
 *  - docs/effects/foo.md (its generated blocks: scripts/gen_effect_docs.py), a C test
 *    tests/c/test_foo.c, and tests/data/recipes_v1/foo.json with every parameter set to
 *    a non-default value (test_recipes_v1 then needs its checksum lines, written once
 *    with LIBFX_WRITE_CHECKSUMS and checked in).
 * In foo.c:
 *  - a params struct and its table (FX_P_FLOAT, FX_P_INT, FX_P_BOOL, FX_P_ENUM,
 *    FX_P_FLOATS, FX_P_STRING, FX_P_MASK below); hint "pixels" for frame-pixel lengths
 *    (the stack divides them on proxies); presets as JSON objects for effects with a
 *    cost knob; a mask parameter arrives parsed (fx_mask_param.spec: build it with
 *    fx_mask_build, add fx_mask_spec_passes to `passes`);
 *  - `passes(params)` for every pass beyond Combined; FX_EFFECT_NEEDS_CAMERA, or
 *    `needs_camera(params)` when it depends on them; `aux_views` for light or rain views;
 *  - `identity(params)` when parameters can make it a no-op (zero strength);
 *  - `validate` for checks between parameters (each one's range is checked already);
 *  - `process(run)`: read run->src, run->frame's passes and run->params; write every
 *    pixel of run->dst inside run->roi and nothing outside it;
 *  - FX_EFFECT_OWN_FINITE / FX_EFFECT_IN_PLACE when they are true (read their notes);
 *  - params_version 1 (0 means 1). Never rename or re-range a parameter without bumping
 *    it and adding a `migrations` step: saved recipes and .blend files must keep loading.
 * What process() may touch: the fx_effect_run fields, fx_frame_find_pass for passes, the
 *  accessors here (fx_effect_scene_time/frame, fx_effect_debug_pass,
 *  fx_effect_finish_row, fx_effect_pass_through), math/ helpers, fx_mask_build for masks
 *  of its own, fx_parallel_for for rows; errors through fx_fail(run->ctx, ..., "%s: ...",
 *  run->where). Never a frame's or the stack's fields directly, never a global.
 * What the stack does for every effect, so no effect repeats it:
 *  - effective parameters: defaults, preset, explicit values, validated once when they
 *    change (load, setter, quality) and handed to every call (passes, run, aux views);
 *  - the passes and the camera checked present, with a message naming what to enable;
 *  - an identity or an empty region (mask selecting nothing) skipped: no call, no copy;
 *  - the mask: built, its bounds as run->roi, outside pixels kept bit for bit, edges
 *    blended by coverage;
 *  - the NaN/Inf guard on the output (replaced and counted in a warning);
 *  - buffers (ping-pong, in place, consumed inputs), progress, cancel and timings;
 *  - proxies: "pixels" parameters and mask rectangles scaled; run->proxy_factor for the
 *    effect's own fixed pixel distances.
 */
#ifndef LIBFX_EFFECT_H
#define LIBFX_EFFECT_H

#include "core/internal.h"
#include "core/mask.h"
#include "core/passes.h"

#include <stdatomic.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define FX_STRING_PARAM_MAX 1024

typedef struct fx_param_def {
    fx_param_info info;
    size_t offset; /* FLOAT: float, INT/BOOL/ENUM: int, FLOATS: float[count],
                      STRING: char[FX_STRING_PARAM_MAX], a mask (FX_P_MASK): fx_mask_param */
} fx_param_def;

/* A parameter that selects pixels as a mask does (materials, objects, indices, a
 * rectangle): a string holding a mask JSON object, hint "mask". The stack parses it once
 * per commit (a bad mask is refused at set time, naming the parameter), scales its
 * rectangle on proxies, and hands process() the result as `spec`. */
typedef struct fx_mask_param {
    char json[FX_STRING_PARAM_MAX]; /* first: the string parameter's storage */
    const fx_mask_spec *spec;       /* in effective params: NULL when nothing is given
                                       ("" or {}); owned by the stack */
} fx_mask_param;

/* Table-building macros: FX_P_FLOAT(struct, field, "name", default, min, max, soft_min, soft_max, hint, doc) */
#define FX_P_FLOAT(st, field, nm, def, lo, hi, slo, shi, hint_, doc_)                                      \
    { { sizeof(fx_param_info), nm, doc_, FX_PARAM_FLOAT, hint_, def, lo, hi, slo, shi, 1, NULL, NULL, 0, NULL }, \
      offsetof(st, field) }
#define FX_P_INT(st, field, nm, def, lo, hi, slo, shi, hint_, doc_)                                        \
    { { sizeof(fx_param_info), nm, doc_, FX_PARAM_INT, hint_, def, lo, hi, slo, shi, 1, NULL, NULL, 0, NULL },   \
      offsetof(st, field) }
#define FX_P_BOOL(st, field, nm, def, doc_)                                                                 \
    { { sizeof(fx_param_info), nm, doc_, FX_PARAM_BOOL, "", def, 0, 1, 0, 1, 1, NULL, NULL, 0, NULL },           \
      offsetof(st, field) }
/* items: a static const char *const[]; def: index of the default item */
#define FX_P_ENUM(st, field, nm, def, items, doc_)                                                          \
    { { sizeof(fx_param_info), nm, doc_, FX_PARAM_ENUM, "", def, 0, (double)(sizeof(items) / sizeof(items[0]) - 1), \
        0, (double)(sizeof(items) / sizeof(items[0]) - 1), 1, NULL, items,                                    \
        (int)(sizeof(items) / sizeof(items[0])), NULL },                                                      \
      offsetof(st, field) }
/* defaults: a static const float[count] */
#define FX_P_FLOATS(st, field, nm, count_, defaults, lo, hi, hint_, doc_)                                   \
    { { sizeof(fx_param_info), nm, doc_, FX_PARAM_FLOATS, hint_, 0, lo, hi, lo, hi, count_, defaults, NULL, 0, NULL }, \
      offsetof(st, field) }
#define FX_P_STRING(st, field, nm, def, hint_, doc_)                                                        \
    { { sizeof(fx_param_info), nm, doc_, FX_PARAM_STRING, hint_, 0, 0, 0, 0, 0, 1, NULL, NULL, 0, def },      \
      offsetof(st, field) }
/* field: an fx_mask_param; its default selects nothing */
#define FX_P_MASK(st, field, nm, doc_)                                                                      \
    { { sizeof(fx_param_info), nm, doc_, FX_PARAM_STRING, FX_HINT_MASK, 0, 0, 0, 0, 0, 1, NULL, NULL, 0, "" }, \
      offsetof(st, field.json) }
#define FX_HINT_MASK "mask"
/* Whether a table entry is a mask parameter (FX_P_MASK). */
int fx_param_is_mask(const fx_param_def *def);

#define FX_COUNT_OF(a) ((int)(sizeof(a) / sizeof((a)[0])))

/* An auxiliary view an effect reads (a light's depth view, the rain map): the add-on
 * renders exactly the views the stack's effects ask for (fx_stack_required_aux_views). */
typedef struct fx_aux_need {
    char name[FX_NAME_MAX];     /* "light:Sun" ("light:" = the scene's first sun), "rain_map", "probe:" */
    const char *kind;           /* "light", "rain_map" or "probe" */
    char light[FX_NAME_MAX];    /* for kind "light": the light's name, "" = the first sun */
    int per_mask;               /* 1: a view of this entry's mask (a mirror's probe): the stack
                                   appends the entry's mask key (fx_effect_run.mask_key) to
                                   name and lists the mask, so the add-on knows where to render */
    float samples_scale;        /* > 0: the view's samples per pixel as a multiple of the render's
                                   (a planar view: ssr_mirror's planar_samples); 0: the add-on's own */
} fx_aux_need;

/* Everything process() gets. */
typedef struct fx_effect_run {
    fx_context *ctx;
    const fx_frame *frame;  /* the input frame: every pass the stack decoded */
    const float *src;       /* current Combined RGBA (after the previous effects), width*height*4 */
    float *dst;             /* output RGBA: process() must fill every pixel inside roi and
                               write nothing outside it (the stack copies only what changed) */
    int width, height;
    fx_rect roi;            /* pixels whose output matters (the mask's bounds; the whole frame
                               without a mask). The stack copies src outside roi and blends
                               dst with src inside it by the mask's coverage. */
    const fx_mask *mask;    /* coverage in [0,1], or NULL: every pixel */
    const void *params;     /* the effect's params struct, effective values */
    int quality;            /* fx_quality the preset came from */
    int index;              /* position in the stack, for messages */
    const char *effect_name;
    const char *where;      /* "effect <index> (<name>)": the prefix of this effect's messages */
    fx_frame *debug;        /* add debug passes here ("<name>" is prefixed by the stack), or NULL */
    atomic_size_t *nonfinite; /* FX_EFFECT_OWN_FINITE: fx_effect_finish_row counts here */
    const char *mask_key;   /* the entry's mask as a short stable hash (hex; of "{}" without a
                               mask): names per-mask aux views (fx_aux_need.per_mask) */
    int proxy_factor;       /* 1, or f on a proxy (fx_frame_reduce): a frame pixel is f full
                               pixels wide. Parameters hinted "pixels" come divided by f
                               already; an effect scales its own fixed pixel distances by it */
} fx_effect_run;

/* Class flags. */
/* process() writes only finite values: by construction (posterize, sin_city clamp every
 * value) or by passing rows that may not be through fx_effect_finish_row while they are in
 * cache. The stack then need not read the whole output again to find NaN/Inf (for a
 * per-pixel effect that re-read is a third of its memory traffic). */
#define FX_EFFECT_OWN_FINITE 1u
/* process() may get dst == src (no mask then): it reads each pixel before writing that
 * pixel and nothing else. The stack then writes over a buffer it owns instead of filling
 * a second one: a third less memory traffic, and no fresh pages on a consumed input. */
#define FX_EFFECT_IN_PLACE 2u
/* process() always needs the camera matrices (for a need that depends on the params, use
 * the needs_camera callback instead). */
#define FX_EFFECT_NEEDS_CAMERA 4u

/* One step of a parameter migration (see fx_effect_class.migrations): in a recipe entry
 * written at params_version `from_version`, parameter `old_name` becomes `new_name` (NULL
 * or the same name: kept), its number multiplied by `scale` and `offset` added (scale 0:
 * unchanged; numbers and number arrays only). `note` says why, for the warning. */
typedef struct fx_param_migration {
    int from_version;
    const char *old_name;
    const char *new_name;
    double scale, offset;
    const char *note;
} fx_param_migration;

typedef struct fx_effect_class {
    const char *name;            /* recipe name: "gaussian_blur" */
    const char *doc;             /* one line */
    size_t params_size;          /* sizeof the params struct */
    const fx_param_def *params;
    int param_count;
    /* Quality presets as JSON objects of parameter values ("{\"steps\": 16}"), or NULL
     * for effects without a speed/accuracy trade. Index: fx_quality. */
    const char *presets[4];
    unsigned flags;              /* FX_EFFECT_* */
    /* Passes needed beyond Combined for these params (and the mask's, added by the stack). */
    fx_pass_set (*passes)(const void *params);
    /* Non-zero if these params need camera matrices. NULL: FX_EFFECT_NEEDS_CAMERA decides. */
    int (*needs_camera)(const void *params);
    /* Non-zero if these params make process() the identity (zero strength, zero sigma):
     * the stack then skips the effect as if it were disabled (no copy, no buffer; the
     * image passes through bit for bit). NULL: never. */
    int (*identity)(const void *params);
    /* Auxiliary views these params read: fills up to `max` entries, returns how many.
     * NULL: none. */
    int (*aux_views)(const void *params, fx_aux_need *out, int max);
    /* Non-zero if these params let process() run with dst == src (see FX_EFFECT_IN_PLACE,
     * for effects where it depends on the params). NULL: the flag decides. */
    int (*in_place)(const void *params);
    /* Non-zero if these params make process() write only finite values (see
     * FX_EFFECT_OWN_FINITE, for effects where it depends on the params). NULL: the flag
     * decides. */
    int (*own_finite)(const void *params);
    /* Border pixels read around each output pixel, for a w x h frame. NULL: 0. The stack
     * does not tile and hands process() the whole source image, so no run needs it: it is
     * what `describe` reports (docs, the add-on, bench_all's "local effect" tables), at
     * 1920x1080 because some halos grow with the frame (bloom's pyramid). Keep it exact. */
    int (*halo)(const void *params, int width, int height);
    /* Checks between parameters (each one's range is checked already). NULL: none.
     * On failure, writes a message naming the parameter into err. */
    fx_result (*validate)(const void *params, char *err, size_t err_size);
    fx_result (*process)(const fx_effect_run *run);
    /* The version of the parameter table; 0 means 1. Bump it when a parameter is renamed
     * or its meaning or range changes, and add the steps from the previous version to
     * `migrations` (applied in table order, version after version, each with a warning);
     * `migrate` may handle what a table cannot (from_version -> from_version + 1, on the
     * entry's "params" object; write why into note). Recipes carry "params_version". */
    int params_version;
    const fx_param_migration *migrations;
    int migration_count;
    fx_result (*migrate)(int from_version, struct cJSON *params, char *note, size_t note_size);
} fx_effect_class;

/* The registry, generated by CMake from the files in libfx/src/effects/: a file foo.c must
 * define `const fx_effect_class fx_effect_foo` (shared helpers belong in math/). */
extern const fx_effect_class *const fx_effect_classes[];
extern const int fx_effect_class_count;
const fx_effect_class *fx_effect_find(const char *name);
const fx_param_def *fx_effect_find_param(const fx_effect_class *cls, const char *name);
/* The class's params_version (1 when it declares none). */
int fx_effect_version(const fx_effect_class *cls);
/* Whether these params need the camera (FX_EFFECT_NEEDS_CAMERA or needs_camera()). */
int fx_effect_needs_camera(const fx_effect_class *cls, const void *params);
/* For tests: one extra class fx_effect_find also finds (not listed by fx_effect_count);
 * NULL removes it. Not thread-safe: set it before any stack uses it. */
void fx_effect_register_test_class(const fx_effect_class *cls);

/* Adds a debug output pass "fx<index>_<effect>_<name>" to run->debug (no dots: a dot
 * would read back as a layer separator) and returns its
 * buffer (width*height*channels floats, zeroed); NULL when debug outputs are off
 * (not an error) or on failure (then *result says why). */
float *fx_effect_debug_pass(const fx_effect_run *run, const char *name, int channels, fx_result *result);

/* Replaces NaN (0) and +-Inf (+-FLT_MAX) in n floats of an output row, as the stack
 * does for every effect, and counts them for the stack's warning. */
void fx_effect_finish_row(const fx_effect_run *run, float *row, size_t n);

/* Copies src to dst inside the ROI and returns FX_OK: what an effect does when what it
 * finds at run time (a light behind the camera) makes it the identity. An identity that
 * the parameters alone decide belongs in the class's `identity` predicate instead. */
fx_result fx_effect_pass_through(const fx_effect_run *run);

/* The scene time of the frame in seconds (frame / fps; fps 24 when the frame has none),
 * for animated effects. */
double fx_effect_scene_time(const fx_effect_run *run);
/* The scene frame number of the frame (finite; 1 when the frame has none). */
double fx_effect_scene_frame(const fx_effect_run *run);

/* Parameter storage helpers (core/params.c). */
void fx_params_set_defaults(const fx_effect_class *cls, void *params);

#ifdef __cplusplus
}
#endif
#endif
