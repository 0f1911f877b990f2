/* Channel-name parsing and the channel -> pass plan (io/exr_channels.c), without files. */
#include "testutil.h"

#include "io/exr_channels.h"

#include <string.h>

static fx_exr_chan split(const char *name, const char *const *views, int nv, const char *part_view)
{
    fx_exr_chan c;
    memset(&c, 0, sizeof c);
    fx_exr_split_channel(name, views, nv, part_view, &c);
    c.x_sampling = c.y_sampling = 1;
    c.type = 2;
    return c;
}

#define SPLIT_IS(c, l, p, v, ch)                                                                   \
    CHECK(strcmp((c).layer, l) == 0 && strcmp((c).pass, p) == 0 && strcmp((c).view, v) == 0 &&   \
          strcmp((c).chan, ch) == 0)

static void test_split(void)
{
    const char *views[2] = {"left", "right"};
    fx_exr_chan c;
    c = split("ViewLayer.Combined.R", NULL, 0, NULL);
    SPLIT_IS(c, "ViewLayer", "Combined", "", "R");
    c = split("My.Layer 2.Depth.Z", NULL, 0, NULL);
    SPLIT_IS(c, "My.Layer 2", "Depth", "", "Z");
    c = split("Image.R", NULL, 0, NULL);
    SPLIT_IS(c, "", "Image", "", "R");
    c = split("R", NULL, 0, NULL);
    SPLIT_IS(c, "", "", "", "R");
    c = split("ViewLayer.Combined.right.G", views, 2, NULL);
    SPLIT_IS(c, "ViewLayer", "Combined", "right", "G");
    c = split("ViewLayer.Combined.G", views, 2, NULL); /* no view token: not tied to a view */
    SPLIT_IS(c, "ViewLayer", "Combined", "", "G");
    c = split("right.A", views, 2, NULL);
    SPLIT_IS(c, "", "", "right", "A");
    c = split("A", views, 2, NULL); /* one token: the default view */
    SPLIT_IS(c, "", "", "left", "A");
    c = split("forward.u", views, 2, "right"); /* multipart: the part's view */
    SPLIT_IS(c, "", "forward", "right", "u");
    c = split("left.Combined.left.R", views, 2, NULL); /* a layer named like a view */
    SPLIT_IS(c, "left", "Combined", "left", "R");
    c = split("Layer..R", NULL, 0, NULL);
    SPLIT_IS(c, "Layer", "", "", "R");

    char l[FX_EXR_NAME_MAX];
    fx_exr_channel_letter("red", l);
    CHECK(strcmp(l, "R") == 0);
    fx_exr_channel_letter("x", l);
    CHECK(strcmp(l, "X") == 0);
    fx_exr_channel_letter("mask", l);
    CHECK(strcmp(l, "mask") == 0);
    char t[FX_NAME_MAX];
    fx_exr_crypto_type("crypto_object", t);
    CHECK(strcmp(t, "CryptoObject") == 0);
    fx_exr_crypto_type("CryptoMaterial", t);
    CHECK(strcmp(t, "CryptoMaterial") == 0);
    fx_exr_crypto_type("uCryptoWildcard", t);
    CHECK(strcmp(t, "uCryptoWildcard") == 0);
}

static const fx_exr_plan_pass *find(const fx_exr_plan_pass *p, int n, const char *name)
{
    for (int i = 0; i < n; i++)
        if (strcmp(p[i].name, name) == 0)
            return &p[i];
    return NULL;
}

static void test_plan(fx_context *ctx)
{
    /* Blender render output with Composite beside the view layer; channels sorted as in a file */
    const char *names[] = {"Composite.Combined.A", "Composite.Combined.B", "Composite.Combined.G",
                           "Composite.Combined.R", "ViewLayer.Combined.A", "ViewLayer.Combined.B",
                           "ViewLayer.Combined.G", "ViewLayer.Combined.R", "ViewLayer.Depth.Z",
                           "ViewLayer.DiffDir.B", "ViewLayer.DiffDir.G", "ViewLayer.DiffDir.R",
                           "ViewLayer.IndexMA.X", "ViewLayer.Normal.X", "ViewLayer.Normal.Y",
                           "ViewLayer.Normal.Z", "ViewLayer.CryptoObject00.A", "ViewLayer.CryptoObject00.B",
                           "ViewLayer.CryptoObject00.G", "ViewLayer.CryptoObject00.R", "ViewLayer.Foo.B",
                           "ViewLayer.Foo.G", "ViewLayer.Foo.R"};
    int n = (int)(sizeof names / sizeof names[0]);
    fx_exr_chan chans[32];
    for (int i = 0; i < n; i++)
        chans[i] = split(names[i], NULL, 0, NULL);
    const char *layer = NULL;
    CHECK_OK(ctx, fx_exr_choose_layer(ctx, "x.exr", chans, n, NULL, &layer));
    CHECK(layer && strcmp(layer, "ViewLayer") == 0);
    CHECK_OK(ctx, fx_exr_choose_layer(ctx, "x.exr", chans, n, "Composite", &layer));
    CHECK_FAIL(ctx, fx_exr_choose_layer(ctx, "x.exr", chans, n, "Other", &layer), FX_ERR_INVALID_ARGUMENT,
               "layers: 'Composite', 'ViewLayer'");

    fx_exr_select sel = {"ViewLayer", "", 1, 0};
    fx_exr_plan_pass *plan = NULL;
    int np = 0;
    CHECK_OK(ctx, fx_exr_plan(ctx, "x.exr", chans, n, NULL, 0, &sel, &plan, &np));
    CHECK(np == 7);
    const fx_exr_plan_pass *p = find(plan, np, "Combined");
    CHECK(p && p->channels == 4 && p->src[0] == 7 && p->src[1] == 6 && p->src[2] == 5 && p->src[3] == 4);
    p = find(plan, np, "Normal");
    CHECK(p && p->src[0] == 13 && p->src[2] == 15);
    p = find(plan, np, "DiffDir");
    CHECK(p && p->channels == 3 && p->src[0] == 11 && p->src[2] == 9);
    p = find(plan, np, "Foo"); /* unknown: RGB order restored from the sorted file */
    CHECK(p && p->id == -1 && p->channels == 3 && p->src[0] == 22 && p->src[2] == 20);
    CHECK(find(plan, np, "CryptoObject00") != NULL);
    fx_mem_free(plan);

    /* a stack that needs Depth only: Combined + Depth */
    fx_exr_select need = {"ViewLayer", "", 0, FX_PASS_BIT(FX_PASS_DEPTH)};
    CHECK_OK(ctx, fx_exr_plan(ctx, "x.exr", chans, n, NULL, 0, &need, &plan, &np));
    CHECK(np == 2 && find(plan, np, "Combined") && find(plan, np, "Depth"));
    fx_mem_free(plan);

    /* two view layers: must choose */
    fx_exr_chan two[2] = {split("A.Combined.R", NULL, 0, NULL), split("B b.Combined.R", NULL, 0, NULL)};
    CHECK_FAIL(ctx, fx_exr_choose_layer(ctx, "two.exr", two, 2, NULL, &layer), FX_ERR_INVALID_ARGUMENT,
               "several layers ('A', 'B b')");

    /* File Output node: Image (Combined, no alpha -> 1), Depth.V, IndexOB.V, Normal.X */
    const char *fo[] = {"Depth.V", "Image.B", "Image.G", "Image.R", "IndexOB.V", "Normal.X", "Normal.Y", "Normal.Z"};
    fx_exr_chan fc[8];
    for (int i = 0; i < 8; i++)
        fc[i] = split(fo[i], NULL, 0, NULL);
    fx_exr_select s2 = {"", "", 1, 0};
    CHECK_OK(ctx, fx_exr_plan(ctx, "fo.exr", fc, 8, NULL, 0, &s2, &plan, &np));
    CHECK(np == 4);
    p = find(plan, np, "Combined");
    CHECK(p && p->src[0] == 3 && p->src[3] == -1 && p->fill[3] == 1.0f);
    p = find(plan, np, "Depth");
    CHECK(p && p->channels == 1 && p->src[0] == 0);
    p = find(plan, np, "IndexOB");
    CHECK(p && p->src[0] == 4);
    fx_mem_free(plan);

    /* Blender 5.x render output: the light and index passes under their UI names */
    const char *b5[] = {"ViewLayer.Diffuse Color.B", "ViewLayer.Diffuse Color.G", "ViewLayer.Diffuse Color.R",
                        "ViewLayer.Glossy Direct.R", "ViewLayer.Object Index.X", "ViewLayer.Ambient Occlusion.R",
                        "ViewLayer.Volume Direct.R"};
    fx_exr_chan c5[7];
    for (int i = 0; i < 7; i++)
        c5[i] = split(b5[i], NULL, 0, NULL);
    fx_exr_select s5 = {"ViewLayer", "", 1, 0};
    CHECK_OK(ctx, fx_exr_plan(ctx, "b5.exr", c5, 7, NULL, 0, &s5, &plan, &np));
    p = find(plan, np, "DiffCol");
    CHECK(p && p->id == FX_PASS_DIFF_COL && p->channels == 3 && p->src[0] == 2 && p->src[2] == 0);
    p = find(plan, np, "GlossDir");
    CHECK(p && p->id == FX_PASS_GLOSS_DIR);
    p = find(plan, np, "IndexOB");
    CHECK(p && p->id == FX_PASS_INDEX_OB && p->src[0] == 4);
    CHECK(find(plan, np, "AO") != NULL);
    p = find(plan, np, "Volume Direct"); /* not a pass libfx reads: kept under its own name */
    CHECK(p && p->id == -1);
    fx_mem_free(plan);
    CHECK(fx_pass_is_blendable("Diffuse Color") && !fx_pass_is_blendable("Object Index") &&
          fx_pass_is_blendable("Volume Indirect"));

    /* other tools' Cryptomatte names become the canonical type */
    fx_exr_crypto cr;
    memset(&cr, 0, sizeof cr);
    strcpy(cr.name, "crypto_object");
    strcpy(cr.file_type, "crypto_object");
    strcpy(cr.type, "CryptoObject");
    fx_exr_chan cc[3] = {split("crypto_object00.red", NULL, 0, NULL), split("crypto_object00.alpha", NULL, 0, NULL),
                         split("crypto_object.red", NULL, 0, NULL)};
    CHECK_OK(ctx, fx_exr_plan(ctx, "c.exr", cc, 3, &cr, 1, &s2, &plan, &np));
    p = find(plan, np, "CryptoObject00");
    CHECK(p && p->src[0] == 0 && p->src[3] == 1);
    CHECK(find(plan, np, "crypto_object") != NULL); /* the preview stays as it is */
    fx_mem_free(plan);
}

int main(void)
{
    fx_context *ctx = NULL;
    if (fx_context_new(&ctx, 1) != FX_OK)
        return 1;
    test_split();
    test_plan(ctx);
    fx_context_free(ctx);
    return tu_finish("test_exr_channels");
}
