/* The canonical passes libfx knows, their channels, and how Blender names them (core/passes.h). */
#include "core/passes.h"

#include <ctype.h>
#include <stddef.h>
#include <string.h>

/* Names are Blender's render-output pass names; blender_setting is the ViewLayer
 * property that enables the pass (the add-on turns exactly these on). */
static const fx_pass_desc pass_table[FX_PASS_COUNT] = {
    [FX_PASS_COMBINED] = {"Combined", 4, "RGBA", 0, 1, 0, "use_pass_combined"},
    [FX_PASS_DEPTH] = {"Depth", 1, "Z", 0, 0, 0, "use_pass_z"},
    [FX_PASS_MIST] = {"Mist", 1, "Z", 0, 0, 0, "use_pass_mist"},
    [FX_PASS_NORMAL] = {"Normal", 3, "XYZ", 0, 0, 0, "use_pass_normal"},
    [FX_PASS_POSITION] = {"Position", 3, "XYZ", 0, 0, 0, "use_pass_position"},
    [FX_PASS_VECTOR] = {"Vector", 4, "XYZW", 0, 0, 0, "use_pass_vector"},
    [FX_PASS_UV] = {"UV", 3, "UVA", 0, 0, 0, "use_pass_uv"},
    [FX_PASS_INDEX_OB] = {"IndexOB", 1, "X", 1, 0, 0, "use_pass_object_index"},
    [FX_PASS_INDEX_MA] = {"IndexMA", 1, "X", 1, 0, 0, "use_pass_material_index"},
    [FX_PASS_ALPHA] = {"Alpha", 1, "A", 0, 1, 0, ""},
    [FX_PASS_DIFF_DIR] = {"DiffDir", 3, "RGB", 0, 1, 0, "use_pass_diffuse_direct"},
    [FX_PASS_DIFF_IND] = {"DiffInd", 3, "RGB", 0, 1, 0, "use_pass_diffuse_indirect"},
    [FX_PASS_DIFF_COL] = {"DiffCol", 3, "RGB", 0, 1, 0, "use_pass_diffuse_color"},
    [FX_PASS_GLOSS_DIR] = {"GlossDir", 3, "RGB", 0, 1, 0, "use_pass_glossy_direct"},
    [FX_PASS_GLOSS_IND] = {"GlossInd", 3, "RGB", 0, 1, 0, "use_pass_glossy_indirect"},
    [FX_PASS_GLOSS_COL] = {"GlossCol", 3, "RGB", 0, 1, 0, "use_pass_glossy_color"},
    [FX_PASS_TRANS_DIR] = {"TransDir", 3, "RGB", 0, 1, 0, "use_pass_transmission_direct"},
    [FX_PASS_TRANS_IND] = {"TransInd", 3, "RGB", 0, 1, 0, "use_pass_transmission_indirect"},
    [FX_PASS_TRANS_COL] = {"TransCol", 3, "RGB", 0, 1, 0, "use_pass_transmission_color"},
    [FX_PASS_EMIT] = {"Emit", 3, "RGB", 0, 1, 0, "use_pass_emit"},
    [FX_PASS_ENV] = {"Env", 3, "RGB", 0, 1, 0, "use_pass_environment"},
    [FX_PASS_AO] = {"AO", 3, "RGB", 0, 1, 0, "use_pass_ambient_occlusion"},
    [FX_PASS_SHADOW] = {"Shadow", 3, "RGB", 0, 1, 0, "use_pass_shadow"},
    [FX_PASS_CRYPTO_OBJECT] = {"CryptoObject", 4, "RGBA", 1, 0, 1, "use_pass_cryptomatte_object"},
    [FX_PASS_CRYPTO_MATERIAL] = {"CryptoMaterial", 4, "RGBA", 1, 0, 1, "use_pass_cryptomatte_material"},
    [FX_PASS_CRYPTO_ASSET] = {"CryptoAsset", 4, "RGBA", 1, 0, 1, "use_pass_cryptomatte_asset"},
    [FX_PASS_LIGHT_GROUP] = {"Combined_" FX_LIGHT_GROUP_NAME, 3, "RGB", 0, 1, 0, FX_LIGHT_GROUP_SETTING},
};

const fx_pass_desc *fx_pass_describe(fx_pass_id id)
{
    if ((int)id < 0 || id >= FX_PASS_COUNT)
        return NULL;
    return &pass_table[id];
}

/* Aliases written by other routes: the File Output node names its sockets; Blender 5.0+
 * renamed the light and index passes in its render output (and so in files saved from the
 * Render Result) to their UI names. */
static const struct {
    const char *alias;
    fx_pass_id id;
} pass_aliases[] = {
    {"Image", FX_PASS_COMBINED},
    {"Z", FX_PASS_DEPTH},
    {"Object Index", FX_PASS_INDEX_OB},
    {"Material Index", FX_PASS_INDEX_MA},
    {"Diffuse Direct", FX_PASS_DIFF_DIR},
    {"Diffuse Indirect", FX_PASS_DIFF_IND},
    {"Diffuse Color", FX_PASS_DIFF_COL},
    {"Glossy Direct", FX_PASS_GLOSS_DIR},
    {"Glossy Indirect", FX_PASS_GLOSS_IND},
    {"Glossy Color", FX_PASS_GLOSS_COL},
    {"Transmission Direct", FX_PASS_TRANS_DIR},
    {"Transmission Indirect", FX_PASS_TRANS_IND},
    {"Transmission Color", FX_PASS_TRANS_COL},
    {"Emission", FX_PASS_EMIT},
    {"Environment", FX_PASS_ENV},
    {"Ambient Occlusion", FX_PASS_AO},
};

int fx_pass_lookup(const char *name)
{
    if (!name)
        return -1;
    for (int i = 0; i < FX_PASS_COUNT; i++) {
        const fx_pass_desc *d = &pass_table[i];
        size_t n = strlen(d->name);
        if (d->is_crypto) {
            /* CryptoObject00, CryptoObject01, ...: the name and two digits */
            if (strncmp(name, d->name, n) == 0 && isdigit((unsigned char)name[n]) &&
                isdigit((unsigned char)name[n + 1]) && name[n + 2] == '\0')
                return i;
        } else if (strcmp(name, d->name) == 0) {
            return i;
        }
    }
    for (size_t i = 0; i < sizeof(pass_aliases) / sizeof(pass_aliases[0]); i++)
        if (strcmp(name, pass_aliases[i].alias) == 0)
            return (int)pass_aliases[i].id;
    return -1;
}

int fx_pass_is_blendable(const char *name)
{
    int id = fx_pass_lookup(name);
    if (id >= 0)
        return pass_table[id].is_color && !pass_table[id].categorical;
    /* Blender's volume light passes are not in the table: light, so blendable */
    return name && strncmp(name, "Volume", 6) == 0;
}
