"""Build atrium.blend: a Sponza-like open courtyard with a tree, surrounded by
two storeys of roofed arcades; transparent rain-cover quads along the inner
edges of the arcades; the camera moves from under the south arcade towards
the courtyard (out from under the arcade roof at y = -7).

    blender -b --factory-startup --python blend_scenes/atrium/make_atrium.py

Coordinates: metres, Z up.  Open courtyard x in [-5, 5], y in [-7, 7]; the
arcades are 3 m deep all round (outer walls at x = +-8, y = +-10).
"""

import math
import os
import random
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import scene_common as sc  # noqa: E402

HERE = sc.script_dir(__file__)

CX, CY = 5.0, 7.0           # courtyard half extents (column lines)
DEPTH = 3.0                 # arcade depth
OX, OY = CX + DEPTH, CY + DEPTH
G_FLOOR = 0.15              # ground arcade floor top
G_TOP = 3.5                 # ground columns top (beam underside)
U_FLOOR = 4.3               # upper arcade floor top (slab 3.95 .. 4.3)
U_TOP = 7.2                 # upper columns top
ROOF_LOW, ROOF_HIGH = 7.9, 9.2
OVERHANG = 0.6
TREE_XY = (-0.9, 1.5)
RAIN_COVER_OPACITY = 0.07
LEAF_SEED = 1234
LEAF_COUNT = 1600

# The rainy atrium (issue 7): VSM shadows of the columns and the leaf tree from the
# Sun's light view (the Sun casts no ray-traced shadow: libfx adds them, taking away the
# Sun's direct and bounce light in its light group pass: docs/accuracy_truth.md), the wet
# courtyard, splashes, then the rain in front of everything.  The light view and the
# rain map are auxiliary depth renders the add-on makes because these effects ask.
RECIPE = {
    "version": 1,
    "quality": "final",
    "effects": [
        {"effect": "vsm_shadows", "enabled": True, "params_version": 2,
         "params": {"light": "Sun", "filter_size": 5.0, "bleed_reduction": 0.3,
                    "apply": "light_group"}},
        {"effect": "wet_surfaces", "enabled": True,
         "params": {"darken": 0.35, "specular": 0.8, "edge_softness": 0.4}},
        {"effect": "rain_splashes", "enabled": True,
         "params": {"spacing": 0.35, "size": 0.12, "brightness": 0.6}},
        {"effect": "rain", "enabled": True,
         "params": {"density": 0.35, "brightness": 0.35, "wind_angle": 10.0,
                    "cover_material": "Rain_Cover"}},
    ],
}


# --------------------------------------------------------------------------
# materials
# --------------------------------------------------------------------------

def leaf_alpha(nt):
    """Leaf-shaped cut-out in each card's UV square: opaque where
    |u - 0.5| < 0.46 * sin(pi * v) ** 0.8 (pointed at both ends)."""
    n, l = nt.nodes, nt.links
    tc = n.new("ShaderNodeTexCoord")
    tc.location = (-1200, 600)
    sep = n.new("ShaderNodeSeparateXYZ")
    sep.location = (-1000, 600)
    l.new(tc.outputs["UV"], sep.inputs[0])

    def math_node(op, a, b=None, loc=(0, 0)):
        m = n.new("ShaderNodeMath")
        m.operation = op
        m.location = loc
        for i, v in enumerate((a, b)):
            if v is None:
                continue
            if isinstance(v, (int, float)):
                m.inputs[i].default_value = v
            else:
                l.new(v, m.inputs[i])
        return m.outputs["Value"]

    vpi = math_node('MULTIPLY', sep.outputs["Y"], math.pi, (-800, 500))
    s = math_node('SINE', vpi, None, (-650, 500))
    s = math_node('MAXIMUM', s, 0.0, (-500, 500))
    w = math_node('POWER', s, 0.8, (-350, 500))
    w = math_node('MULTIPLY', w, 0.46, (-200, 500))
    du = math_node('SUBTRACT', sep.outputs["X"], 0.5, (-800, 700))
    du = math_node('ABSOLUTE', du, None, (-650, 700))
    return math_node('LESS_THAN', du, w, (0, 600))


def materials():
    m = {}
    m["Courtyard_Stone"] = sc.principled_material(
        "Courtyard_Stone", (0.6, 0.55, 0.48), 1, roughness=0.7,
        texture=lambda nt, b, c, k: sc.tex_tiles(nt, b, c, k, scale=0.8,
                                                 mortar=(0.3, 0.28, 0.25)), bump=0.3)
    m["Arcade_Stone"] = sc.principled_material(
        "Arcade_Stone", (0.55, 0.32, 0.24), 2, roughness=0.6,
        texture=lambda nt, b, c, k: sc.tex_tiles(nt, b, c, k, scale=1.6,
                                                 mortar=(0.4, 0.35, 0.3)), bump=0.2)
    m["Column_Stone"] = sc.principled_material(
        "Column_Stone", (0.75, 0.7, 0.6), 3, roughness=0.5,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=2.0), bump=0.1)
    m["Beam_Stone"] = sc.principled_material(
        "Beam_Stone", (0.68, 0.6, 0.5), 4, roughness=0.6,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=1.5), bump=0.1)
    m["Roof_Tiles"] = sc.principled_material(
        "Roof_Tiles", (0.62, 0.25, 0.14), 5, roughness=0.55,
        texture=lambda nt, b, c, k: sc.tex_bricks(nt, b, c, k, scale=2.5), bump=0.4)
    m["Wall_Plaster"] = sc.principled_material(
        "Wall_Plaster", (0.8, 0.7, 0.55), 6, roughness=0.85,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=0.8), bump=0.1)
    m["Balustrade_Stone"] = sc.principled_material(
        "Balustrade_Stone", (0.7, 0.66, 0.58), 7, roughness=0.6,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=3.0), bump=0.1)
    m["Bark"] = sc.principled_material(
        "Bark", (0.3, 0.2, 0.12), 10, roughness=0.9, texture=sc.tex_wood, bump=0.6)
    leaves = sc.principled_material(
        "Leaves", (0.16, 0.42, 0.08), 11, roughness=0.5,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=0.6, contrast=0.5),
        Subsurface=0.0)
    sc.mix_with_transparent(leaves, alpha_socket_fn=leaf_alpha)
    sc.compat.material_alpha_clip(leaves, 0.5)
    leaves.use_backface_culling = False
    m["Leaves"] = leaves
    # Only a tinted Transparent BSDF (no reflective closure): a reflective part
    # would be picked stochastically per sample and speckle the cover into the
    # Index/Depth passes.  Cryptomatte still lists the covers with coverage
    # 1 - transparency ~ RAIN_COVER_OPACITY over what lies behind them.
    rain = sc.transparent_material("Rain_Cover", 20, opacity=RAIN_COVER_OPACITY,
                                   tint=(0.97, 0.98, 1.0))
    sc.compat.material_alpha_blend(rain, casts_shadow=False)
    m["Rain_Cover"] = rain
    return m


# --------------------------------------------------------------------------
# geometry
# --------------------------------------------------------------------------

def column_positions():
    """Column centres on the inner edge (courtyard rectangle), corners once."""
    pts = []
    nx, ny = 4, 6                    # bays along x and y
    for i in range(nx + 1):
        x = -CX + 2 * CX * i / nx
        pts += [(x, -CY), (x, CY)]
    for j in range(1, ny):
        y = -CY + 2 * CY * j / ny
        pts += [(-CX, y), (CX, y)]
    return pts


def build_courtyard_floor(bm):
    sc.bm_box_minmax(bm, (-CX, -CY, -0.2), (CX, CY, 0.0))


def build_arcade_floor(bm):
    """Ground arcade floor (raised step) and upper-storey slab, both ring-shaped."""
    for z0, z1 in ((-0.2, G_FLOOR), (U_FLOOR - 0.35, U_FLOOR)):
        sc.bm_box_minmax(bm, (-OX, -OY, z0), (OX, -CY, z1))
        sc.bm_box_minmax(bm, (-OX, CY, z0), (OX, OY, z1))
        sc.bm_box_minmax(bm, (-OX, -CY, z0), (-CX, CY, z1))
        sc.bm_box_minmax(bm, (CX, -CY, z0), (OX, CY, z1))


def build_columns(bm):
    for x, y in column_positions():
        # ground storey: square base, round shaft, square capital
        sc.bm_box(bm, (x, y, G_FLOOR + 0.15), (0.7, 0.7, 0.3))
        sc.bm_cylinder(bm, (x, y, G_FLOOR + 0.3), 0.26, G_TOP - G_FLOOR - 0.55,
                       segments=16, radius_top=0.23)
        sc.bm_box(bm, (x, y, G_TOP - 0.125), (0.65, 0.65, 0.25))
        # upper storey: slimmer
        sc.bm_box(bm, (x, y, U_FLOOR + 0.1), (0.5, 0.5, 0.2))
        sc.bm_cylinder(bm, (x, y, U_FLOOR + 0.2), 0.18, U_TOP - U_FLOOR - 0.4,
                       segments=16, radius_top=0.16)
        sc.bm_box(bm, (x, y, U_TOP - 0.1), (0.5, 0.5, 0.2))


def build_beams(bm):
    """Beams along the column lines at both storeys (the upper-storey slab rests
    on the lower ones) plus transverse beams from each column to the wall."""
    for z0, z1, w in ((G_TOP, U_FLOOR - 0.35, 0.6), (U_TOP, U_TOP + 0.45, 0.45)):
        sc.bm_box_minmax(bm, (-CX - w / 2, -CY - w / 2, z0), (CX + w / 2, -CY + w / 2, z1))
        sc.bm_box_minmax(bm, (-CX - w / 2, CY - w / 2, z0), (CX + w / 2, CY + w / 2, z1))
        sc.bm_box_minmax(bm, (-CX - w / 2, -CY, z0), (-CX + w / 2, CY, z1))
        sc.bm_box_minmax(bm, (CX - w / 2, -CY, z0), (CX + w / 2, CY, z1))
    for x, y in column_positions():
        if abs(y) == CY and abs(x) < CX:
            sc.bm_box_minmax(bm, (x - 0.15, min(y, math.copysign(OY, y)), G_TOP - 0.3),
                             (x + 0.15, max(y, math.copysign(OY, y)), G_TOP))
        elif abs(x) == CX and abs(y) < CY:
            sc.bm_box_minmax(bm, (min(x, math.copysign(OX, x)), y - 0.15, G_TOP - 0.3),
                             (max(x, math.copysign(OX, x)), y + 0.15, G_TOP))


def build_balustrade(bm):
    """Low parapet wall between the upper columns."""
    h = U_FLOOR + 0.95
    t = 0.18
    sc.bm_box_minmax(bm, (-CX, -CY - t / 2, U_FLOOR), (CX, -CY + t / 2, h))
    sc.bm_box_minmax(bm, (-CX, CY - t / 2, U_FLOOR), (CX, CY + t / 2, h))
    sc.bm_box_minmax(bm, (-CX - t / 2, -CY, U_FLOOR), (-CX + t / 2, CY, h))
    sc.bm_box_minmax(bm, (CX - t / 2, -CY, U_FLOOR), (CX + t / 2, CY, h))


def _slab(bm, top, thickness):
    """Prism under the quad ``top`` (4 corners, counter-clockwise from above)."""
    vt = [bm.verts.new(p) for p in top]
    vb = [bm.verts.new((p[0], p[1], p[2] - thickness)) for p in top]
    bm.faces.new(vt)
    bm.faces.new(list(reversed(vb)))
    for i in range(4):
        j = (i + 1) % 4
        bm.faces.new((vb[i], vb[j], vt[j], vt[i]))


def build_roof(bm):
    """Lean-to roofs sloping down towards the courtyard, overhanging the columns."""
    ix, iy = CX - OVERHANG, CY - OVERHANG
    lo, hi = ROOF_LOW, ROOF_HIGH
    t = 0.25
    _slab(bm, [(-OX, -OY, hi), (OX, -OY, hi), (ix, -iy, lo), (-ix, -iy, lo)], t)   # south
    _slab(bm, [(OX, OY, hi), (-OX, OY, hi), (-ix, iy, lo), (ix, iy, lo)], t)       # north
    _slab(bm, [(-OX, OY, hi), (-OX, -OY, hi), (-ix, -iy, lo), (-ix, iy, lo)], t)   # west
    _slab(bm, [(OX, -OY, hi), (OX, OY, hi), (ix, iy, lo), (ix, -iy, lo)], t)       # east
    # a ridge cap along the outer walls
    sc.bm_box_minmax(bm, (-OX - 0.3, -OY - 0.3, hi - 0.25), (OX + 0.3, -OY + 0.3, hi + 0.15))
    sc.bm_box_minmax(bm, (-OX - 0.3, OY - 0.3, hi - 0.25), (OX + 0.3, OY + 0.3, hi + 0.15))
    sc.bm_box_minmax(bm, (-OX - 0.3, -OY, hi - 0.25), (-OX + 0.3, OY, hi + 0.15))
    sc.bm_box_minmax(bm, (OX - 0.3, -OY, hi - 0.25), (OX + 0.3, OY, hi + 0.15))


def build_walls(bm):
    t = 0.4
    top = ROOF_HIGH - 0.2
    sc.bm_box_minmax(bm, (-OX - t, -OY - t, -0.2), (OX + t, -OY, top))
    sc.bm_box_minmax(bm, (-OX - t, OY, -0.2), (OX + t, OY + t, top))
    sc.bm_box_minmax(bm, (-OX - t, -OY, -0.2), (-OX, OY, top))
    sc.bm_box_minmax(bm, (OX, -OY, -0.2), (OX + t, OY, top))


def build_trunk(bm):
    x, y = TREE_XY
    sc.bm_segment(bm, (x, y, -0.1), (x + 0.1, y, 2.4), 0.32, 0.2, segments=16)
    sc.bm_segment(bm, (x + 0.1, y, 2.4), (x + 0.15, y + 0.1, 4.4), 0.2, 0.1, segments=12)
    sc.bm_sphere(bm, (x + 0.1, y, 2.4), 0.2, segments=12, rings=8)
    branches = [((1.6, 0.4, 4.2), 0.11), ((-1.4, 0.9, 4.0), 0.1), ((0.3, -1.6, 4.3), 0.1),
                ((-0.5, -0.9, 5.0), 0.08), ((0.9, 1.4, 5.1), 0.08)]
    for (dx, dy, z), r in branches:
        sc.bm_segment(bm, (x + 0.1, y, 2.4 + (z - 4.0) * 0.8), (x + dx, y + dy, z), r, r * 0.4,
                      segments=8)
    # roots flare
    for a in range(5):
        ang = 2 * math.pi * a / 5 + 0.3
        sc.bm_segment(bm, (x, y, 0.35), (x + 0.7 * math.cos(ang), y + 0.7 * math.sin(ang), -0.05),
                      0.12, 0.04, segments=8)


def build_leaves(bm):
    """LEAF_COUNT small cards in an ellipsoidal crown, deterministic (seeded).
    Every card has UVs 0..1 (the leaf shape is cut out by the material)."""
    from mathutils import Euler, Vector
    rng = random.Random(LEAF_SEED)
    uv_layer = bm.loops.layers.uv.new("UVMap")
    cx, cy = TREE_XY
    center = Vector((cx + 0.1, cy + 0.1, 5.0))
    radii = Vector((2.7, 2.7, 1.9))
    uvs = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    for _ in range(LEAF_COUNT):
        # rejection-sample the crown shell (denser near the surface)
        while True:
            p = Vector((rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)))
            if 0.35 < p.length <= 1.0:
                break
        pos = center + Vector((p.x * radii.x, p.y * radii.y, p.z * radii.z))
        size = rng.uniform(0.7, 1.15)
        w, h = 0.22 * size, 0.36 * size
        rot = Euler((rng.uniform(-1.2, 1.2), rng.uniform(-1.2, 1.2),
                     rng.uniform(0, 2 * math.pi)), 'XYZ').to_matrix()
        corners = [(-w / 2, 0.0), (w / 2, 0.0), (w / 2, h), (-w / 2, h)]
        vs = [bm.verts.new(pos + rot @ Vector((a, b, 0.0))) for a, b in corners]
        f = bm.faces.new(vs)
        for loop, uv in zip(f.loops, uvs):
            loop[uv_layer].uv = uv


def rain_cover_quads():
    """(name, corners) of the vertical cover quads on the inner arcade edges,
    from each storey's floor to its beams, facing the courtyard."""
    out = []
    for level, z0, z1 in (("Ground", G_FLOOR, G_TOP), ("Upper", U_FLOOR, U_TOP)):
        out.append(("RainCover_%s_South" % level,
                    [(-CX, -CY, z0), (CX, -CY, z0), (CX, -CY, z1), (-CX, -CY, z1)]))
        out.append(("RainCover_%s_North" % level,
                    [(CX, CY, z0), (-CX, CY, z0), (-CX, CY, z1), (CX, CY, z1)]))
        out.append(("RainCover_%s_West" % level,
                    [(-CX, CY, z0), (-CX, -CY, z0), (-CX, -CY, z1), (-CX, CY, z1)]))
        out.append(("RainCover_%s_East" % level,
                    [(CX, -CY, z0), (CX, CY, z0), (CX, CY, z1), (CX, -CY, z1)]))
    return out


def main():
    scene = sc.reset_file()
    scene.name = "Atrium"
    sc.render_settings(scene)
    scene.cycles.transparent_max_bounces = 24   # stacked leaf cards
    # view_layer.pass_alpha_threshold stays at its default 0.5: Depth/Index/
    # Normal passes see *through* the rain covers (opacity 0.07) and the cut-out
    # parts of the leaf cards; Cryptomatte lists the covers with coverage ~0.07
    # on top of what lies behind them.  (A lower threshold would put the covers
    # into IndexOB/Depth and hide the whole courtyard behind them.)
    m = materials()

    sun_dir = sc.direction_from_angles(-150.0, 52.0)
    sc.sky_world("Sky_Atrium", zenith=(0.15, 0.35, 0.85), horizon=(0.7, 0.82, 0.95),
                 ground=(0.3, 0.28, 0.25), strength=1.8)
    sun = sc.add_sun("Sun", sun_dir, strength=4.5, color=(1.0, 0.93, 0.8), angle_deg=1.5)
    # libfx's vsm_shadows adds the Sun's shadows (apply "light_group": the Sun's whole share,
    # from the light group pass the add-on makes): Cycles must not.
    # tests/bench/bench_atrium.py renders the ray-traced truth with this switched on.
    sc.compat.light_cast_shadow(sun.data, False)

    sc.mesh_object("Courtyard_Floor", build_courtyard_floor, m["Courtyard_Stone"], 1)
    sc.mesh_object("Arcade_Floor", build_arcade_floor, m["Arcade_Stone"], 2)
    sc.mesh_object("Arcade_Columns", build_columns, m["Column_Stone"], 3, smooth=True,
                   auto_smooth_deg=40)
    sc.mesh_object("Arcade_Beams", build_beams, m["Beam_Stone"], 4)
    sc.mesh_object("Arcade_Roof", build_roof, m["Roof_Tiles"], 5)
    sc.mesh_object("Atrium_Walls", build_walls, m["Wall_Plaster"], 6)
    sc.mesh_object("Balustrade", build_balustrade, m["Balustrade_Stone"], 7)
    sc.mesh_object("Tree_Trunk", build_trunk, m["Bark"], 10, smooth=True,
                   auto_smooth_deg=50)
    sc.mesh_object("Tree_Leaves", build_leaves, m["Leaves"], 11)
    covers = sc.new_collection("RainCovers")
    for i, (name, corners) in enumerate(rain_cover_quads()):
        o = sc.mesh_object(name, lambda bm, c=corners: sc.bm_quad(bm, c), m["Rain_Cover"],
                           20 + i, collection=covers)
        # camera-only helpers: they must not shadow or tint the lighting
        o.visible_shadow = False
        o.visible_diffuse = False
        o.visible_glossy = False
        o.visible_transmission = False
        o.visible_volume_scatter = False

    cam = sc.add_camera("Camera", lens=20.0)
    sc.animate_camera(cam, [
        (1, (-1.3, -9.3, 1.7), (-0.6, 2.0, 4.2)),
        (8, (-1.0, -5.6, 1.75), (-0.4, 4.0, 3.2)),
    ])

    sc.check_unique_indices()
    sc.write_recipe(HERE, RECIPE)
    sc.print_index_table()
    sc.save_blend(os.path.join(HERE, "atrium.blend"))


if __name__ == "__main__":
    sc.run_main(main)
