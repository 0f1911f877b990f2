"""Build greek_bath.blend: a roofed bath hall with a pool, a colonnade open to a
low sun (visible between the columns: god rays) and a marble statue on a plinth
(censored by object name in the recipe).

    blender -b --factory-startup --python blend_scenes/greek_bath/make_greek_bath.py

Coordinates: metres, Z up.  The hall spans x in [-9, 9], y in [-8, 6.9]; the
open colonnade is the +Y side (columns on y = 6.5); the sun stands low in +Y.
The camera sits at the back of the hall (y ~ -7) looking +Y over the pool.
"""

import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import scene_common as sc  # noqa: E402

HERE = sc.script_dir(__file__)

HALL_X = 9.0
HALL_Y0, HALL_Y1 = -8.0, 6.9
COLUMN_Y = 6.5
COLUMN_H = 6.0
ROOF_Z = 6.6
POOL = (-3.5, 3.5, -3.0, 3.5)   # x0, x1, y0, y1
POOL_DEPTH = 1.2
WATER_Z = -0.15
FLOOR_T = 0.3
STATUE_XY = (-4.6, 0.2)
SUN_AZIMUTH = -13.5   # degrees from +Y (negative: towards +X)
SUN_ELEVATION = 10.0

STATUE_ANCHOR = (STATUE_XY[0], STATUE_XY[1], 2.0)   # chest height: the censor grid's corner

# The bath's stack: caustics on the water (by material name, world-anchored from the
# Position pass, animated by the frame time), crepuscular rays from the `Sun` through
# the colonnade (sky mask from Depth: bright walls cast none), then the censored statue
# (cells anchored to a world point on it, so they stay put while the camera moves).
RECIPE = {
    "version": 1,
    "quality": "final",
    "effects": [
        # params_version 3 (issue 27) with interior 0 and warp 0: the bath keeps its look of before
        {"effect": "voronoi_caustics", "enabled": True, "params_version": 3,
         "params": {"mode": "physical", "points": 196, "tile_size": 3.0, "strength": 0.8,
                    "line_width": 0.12, "speed": 2.0, "environment_strength": 0.25,
                    "world_color": [0.55, 0.7, 0.95], "interior": 0.0, "warp": 0.0},
         "mask": {"material": "Water"}},
        {"effect": "god_rays", "enabled": True,
         "params": {"light": "Sun", "occlusion": "sky", "threshold": 0.9, "knee": 0.5,
                    "max_source": 6.0, "decay": 0.975, "density": 0.95, "weight": 1.0,
                    "exposure": 0.006}},
        {"effect": "pixelate", "enabled": True,
         "params": {"mode": "cells", "cell_size": 12, "anchor": "world",
                    "world_point_auto": False, "world_point": list(STATUE_ANCHOR)},
         "mask": {"object": "Statue"}},
    ],
}


def materials():
    m = {}
    m["Floor_Stone"] = sc.principled_material(
        "Floor_Stone", (0.62, 0.57, 0.5), 1, roughness=0.55,
        texture=lambda nt, b, c, k: sc.tex_tiles(nt, b, c, k, scale=0.5,
                                                 mortar=(0.35, 0.32, 0.28)),
        bump=0.3)
    m["Pool_Tiles"] = sc.principled_material(
        "Pool_Tiles", (0.15, 0.45, 0.6), 2, roughness=0.25,
        texture=lambda nt, b, c, k: sc.tex_tiles(nt, b, c, k, scale=4.0,
                                                 mortar=(0.85, 0.85, 0.85),
                                                 mortar_size=0.06),
        bump=0.2)
    water = sc.principled_material(
        "Water", (0.8, 0.95, 1.0), 3, roughness=0.02, IOR=1.333, Transmission=1.0)
    _water_waves(water)
    m["Water"] = water
    m["Marble_Column"] = sc.principled_material(
        "Marble_Column", (0.88, 0.85, 0.8), 4, roughness=0.3,
        texture=lambda nt, b, c, k: sc.tex_marble(nt, b, c, k, scale=0.8), bump=0.05)
    m["Roof_Plaster"] = sc.principled_material(
        "Roof_Plaster", (0.7, 0.55, 0.42), 5, roughness=0.8,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=1.0), bump=0.1)
    m["Wall_Plaster"] = sc.principled_material(
        "Wall_Plaster", (0.78, 0.62, 0.45), 6, roughness=0.85,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=0.7), bump=0.1)
    m["Ground_Sand"] = sc.principled_material(
        "Ground_Sand", (0.7, 0.6, 0.42), 7, roughness=0.9,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=0.3), bump=0.0)
    m["Statue_Marble"] = sc.principled_material(
        "Statue_Marble", (0.92, 0.9, 0.86), 8, roughness=0.35,
        texture=lambda nt, b, c, k: sc.tex_marble(nt, b, c, k, scale=3.0), bump=0.0)
    m["Plinth_Stone"] = sc.principled_material(
        "Plinth_Stone", (0.5, 0.47, 0.44), 9, roughness=0.6,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=3.0), bump=0.2)
    return m


def _water_waves(mat):
    """Small procedural ripples as a bump (water surface stays a flat quad)."""
    nt = mat.node_tree
    bsdf = nt.nodes.get("Principled BSDF")
    tc = nt.nodes.new("ShaderNodeTexCoord")
    mp = nt.nodes.new("ShaderNodeMapping")
    mp.inputs["Scale"].default_value = (1.0, 1.6, 1.0)
    nt.links.new(tc.outputs["Object"], mp.inputs["Vector"])
    n = nt.nodes.new("ShaderNodeTexNoise")
    n.inputs["Scale"].default_value = 1.3
    n.inputs["Detail"].default_value = 3.0
    nt.links.new(mp.outputs["Vector"], n.inputs["Vector"])
    b = nt.nodes.new("ShaderNodeBump")
    b.inputs["Strength"].default_value = 0.25
    b.inputs["Distance"].default_value = 0.1
    nt.links.new(n.outputs["Fac"], b.inputs["Height"])
    nt.links.new(b.outputs["Normal"], bsdf.inputs["Normal"])


def build_floor(bm):
    """Hall floor (top at z=0) with a hole for the pool, plus the colonnade step."""
    x0, x1, y0, y1 = POOL
    z = (-FLOOR_T, 0.0)
    sc.bm_box_minmax(bm, (-HALL_X, HALL_Y0, z[0]), (HALL_X, y0, z[1]))
    sc.bm_box_minmax(bm, (-HALL_X, y1, z[0]), (HALL_X, COLUMN_Y + 1.0, z[1]))
    sc.bm_box_minmax(bm, (-HALL_X, y0, z[0]), (x0, y1, z[1]))
    sc.bm_box_minmax(bm, (x1, y0, z[0]), (HALL_X, y1, z[1]))


def build_pool(bm):
    x0, x1, y0, y1 = POOL
    t = 0.1
    d = -POOL_DEPTH
    sc.bm_box_minmax(bm, (x0, y0, d - t), (x1, y1, d))            # pool floor
    sc.bm_box_minmax(bm, (x0, y0, d), (x0 + t, y1, -0.001))       # walls (inside the hole)
    sc.bm_box_minmax(bm, (x1 - t, y0, d), (x1, y1, -0.001))
    sc.bm_box_minmax(bm, (x0, y0, d), (x1, y0 + t, -0.001))
    sc.bm_box_minmax(bm, (x0, y1 - t, d), (x1, y1, -0.001))


def build_water(bm):
    x0, x1, y0, y1 = POOL
    t = 0.1
    sc.bm_quad(bm, [(x0 + t, y0 + t, WATER_Z), (x1 - t, y0 + t, WATER_Z),
                    (x1 - t, y1 - t, WATER_Z), (x0 + t, y1 - t, WATER_Z)])


def build_column(x):
    def build(bm):
        y = COLUMN_Y
        sc.bm_box(bm, (x, y, 0.15), (0.95, 0.95, 0.3))                 # plinth
        sc.bm_cylinder(bm, (x, y, 0.3), 0.42, 0.15, segments=24)        # torus-ish base
        sc.bm_cylinder(bm, (x, y, 0.45), 0.36, COLUMN_H - 0.95, segments=20,
                       radius_top=0.3)                                  # tapered shaft
        sc.bm_cylinder(bm, (x, y, COLUMN_H - 0.5), 0.3, 0.2, segments=20,
                       radius_top=0.45)                                 # echinus
        sc.bm_box(bm, (x, y, COLUMN_H - 0.15), (1.0, 1.0, 0.3))         # abacus
    return build


def build_roof(bm):
    """Architrave over the columns and a flat roof with a skylight over the pool."""
    z0, z1 = ROOF_Z, ROOF_Z + 0.35
    sc.bm_box_minmax(bm, (-HALL_X - 0.3, COLUMN_Y - 0.5, COLUMN_H),
                     (HALL_X + 0.3, COLUMN_Y + 0.5, z0))                # architrave
    sky = (-2.0, 2.0, -1.5, 2.5)
    sc.bm_box_minmax(bm, (-HALL_X - 0.3, HALL_Y0 - 0.3, z0), (HALL_X + 0.3, sky[2], z1))
    sc.bm_box_minmax(bm, (-HALL_X - 0.3, sky[3], z0), (HALL_X + 0.3, COLUMN_Y + 0.6, z1))
    sc.bm_box_minmax(bm, (-HALL_X - 0.3, sky[2], z0), (sky[0], sky[3], z1))
    sc.bm_box_minmax(bm, (sky[1], sky[2], z0), (HALL_X + 0.3, sky[3], z1))


def build_walls(bm):
    t = 0.3
    sc.bm_box_minmax(bm, (-HALL_X - t, HALL_Y0 - t, -FLOOR_T), (HALL_X + t, HALL_Y0, ROOF_Z))
    sc.bm_box_minmax(bm, (-HALL_X - t, HALL_Y0, -FLOOR_T), (-HALL_X, COLUMN_Y + 0.5, ROOF_Z))
    sc.bm_box_minmax(bm, (HALL_X, HALL_Y0, -FLOOR_T), (HALL_X + t, COLUMN_Y + 0.5, ROOF_Z))


def build_ground(bm):
    sc.bm_box_minmax(bm, (-120.0, COLUMN_Y + 1.0, -0.6), (120.0, 200.0, -0.3))


def build_plinth(bm):
    x, y = STATUE_XY
    sc.bm_box(bm, (x, y, 0.06), (1.25, 1.25, 0.12))
    sc.bm_box(bm, (x, y, 0.55), (1.0, 1.0, 0.9))
    sc.bm_box(bm, (x, y, 1.05), (1.15, 1.15, 0.1))


def build_statue(bm):
    """A contrapposto standing figure from primitives, in local space (feet at
    z=0, facing -Y); the object is placed on the plinth and turned to the camera."""
    # legs: weight on the right leg, left knee bent forward
    sc.bm_segment(bm, (0.1, 0, 0.95), (0.11, 0.0, 0.5), 0.085, 0.06)
    sc.bm_segment(bm, (0.11, 0.0, 0.5), (0.12, 0.02, 0.08), 0.06, 0.045)
    sc.bm_segment(bm, (-0.1, 0, 0.93), (-0.14, -0.08, 0.5), 0.085, 0.06)
    sc.bm_segment(bm, (-0.14, -0.08, 0.5), (-0.18, 0.05, 0.1), 0.06, 0.045)
    sc.bm_sphere(bm, (0.11, 0.0, 0.5), 0.062, segments=12, rings=8)
    sc.bm_sphere(bm, (-0.14, -0.08, 0.5), 0.062, segments=12, rings=8)
    sc.bm_box(bm, (0.12, -0.06, 0.035), (0.1, 0.24, 0.07))       # feet
    sc.bm_box(bm, (-0.19, 0.0, 0.06), (0.1, 0.24, 0.07), rot_deg=(-20, 0, 10))
    # pelvis, torso, chest
    sc.bm_sphere(bm, (0, 0, 0.98), 1.0, scale=(0.19, 0.12, 0.12), segments=16, rings=10)
    sc.bm_sphere(bm, (0, 0, 1.18), 1.0, scale=(0.16, 0.11, 0.2), segments=16, rings=10)
    sc.bm_sphere(bm, (0, 0.0, 1.36), 1.0, scale=(0.22, 0.13, 0.14), segments=16, rings=10,
                 rot_deg=(0, 6, 0))
    # neck and head
    sc.bm_segment(bm, (0, 0, 1.45), (0.0, -0.01, 1.58), 0.055, 0.05)
    sc.bm_sphere(bm, (0.0, -0.02, 1.68), 1.0, scale=(0.095, 0.11, 0.125), segments=16,
                 rings=12)
    sc.bm_sphere(bm, (0.0, -0.12, 1.67), 1.0, scale=(0.02, 0.025, 0.035), segments=8,
                 rings=6)                                         # nose
    sc.bm_sphere(bm, (0.0, 0.03, 1.74), 1.0, scale=(0.1, 0.1, 0.08), segments=12,
                 rings=8)                                         # hair
    # right arm hanging, left arm raised (holding a bowl)
    sc.bm_sphere(bm, (0.23, 0, 1.42), 0.07, segments=12, rings=8)
    sc.bm_segment(bm, (0.23, 0, 1.42), (0.28, 0.02, 1.14), 0.055, 0.045)
    sc.bm_segment(bm, (0.28, 0.02, 1.14), (0.3, -0.03, 0.9), 0.045, 0.035)
    sc.bm_sphere(bm, (0.3, -0.04, 0.86), 1.0, scale=(0.035, 0.03, 0.05), segments=8, rings=6)
    sc.bm_sphere(bm, (-0.23, 0, 1.42), 0.07, segments=12, rings=8)
    sc.bm_segment(bm, (-0.23, 0, 1.42), (-0.38, -0.05, 1.62), 0.055, 0.045)
    sc.bm_segment(bm, (-0.38, -0.05, 1.62), (-0.33, -0.12, 1.88), 0.045, 0.035)
    sc.bm_cylinder(bm, (-0.32, -0.12, 1.9), 0.08, 0.06, segments=16, radius_top=0.12)


def main():
    scene = sc.reset_file()
    scene.name = "GreekBath"
    sc.render_settings(scene)
    m = materials()

    sun_dir = sc.direction_from_angles(SUN_AZIMUTH, SUN_ELEVATION)
    sc.sky_world("Sky_Bath", zenith=(0.2, 0.42, 0.9), horizon=(0.95, 0.85, 0.7),
                 ground=(0.45, 0.38, 0.28), strength=1.0, sun_dir=sun_dir,
                 sun_color=(1.0, 0.9, 0.7), sun_strength=60.0, sun_size_deg=3.0,
                 glow_strength=4.0, glow_size_deg=18.0)
    sc.add_sun("Sun", sun_dir, strength=5.0, color=(1.0, 0.88, 0.7), angle_deg=1.0)

    objs = []
    objs.append(sc.mesh_object("Floor_Stone", build_floor, m["Floor_Stone"], 1))
    objs.append(sc.mesh_object("Pool_Basin", build_pool, m["Pool_Tiles"], 2))
    water = sc.mesh_object("Pool_Water", build_water, m["Water"], 3)
    # Let the sun light the pool floor through the water (a refractive surface
    # otherwise blocks shadow rays and leaves the basin to slow caustic paths).
    water.visible_shadow = False
    objs.append(water)
    objs.append(sc.mesh_object("Roof", build_roof, m["Roof_Plaster"], 4))
    objs.append(sc.mesh_object("Hall_Walls", build_walls, m["Wall_Plaster"], 5))
    objs.append(sc.mesh_object("Ground_Outside", build_ground, m["Ground_Sand"], 6))
    plinth = sc.mesh_object("Statue_Plinth", build_plinth, m["Plinth_Stone"], 21)
    statue = sc.mesh_object("Statue", build_statue, m["Statue_Marble"], 20, smooth=True)
    statue.location = (STATUE_XY[0], STATUE_XY[1], 1.1)
    statue.rotation_euler = (0, 0, math.radians(-28))   # face the camera
    statue.scale = (1.05, 1.05, 1.05)
    objs += [plinth, statue]
    cols = sc.new_collection("Colonnade")
    for i, x in enumerate(range(-8, 9, 2)):
        objs.append(sc.mesh_object("Column_%02d" % (i + 1), build_column(float(x)),
                                   m["Marble_Column"], 10 + i, smooth=True,
                                   auto_smooth_deg=40, collection=cols))

    # Direct fills keep 16 un-denoised samples readable (an interior lit only by
    # bounce light is grainy): a key on the statue side from behind the camera and
    # a soft up-facing "floor bounce" under the roof.
    sc.add_area_light("Fill_Light", (-1.0, -7.0, 5.0), (-4.0, 1.0, 1.8), size=(5.0, 2.0),
                      power=1000.0, color=(1.0, 0.95, 0.9), shadow=True)
    sc.add_area_light("Bounce_Light", (0.0, -1.0, 0.6), (0.0, -1.0, 10.0),
                      size=(16.0, 12.0), power=700.0, color=(1.0, 0.85, 0.65),
                      shadow=False)

    cam = sc.add_camera("Camera", lens=22.0)
    sc.animate_camera(cam, [
        (1, (-0.7, -7.0, 1.9), (0.2, 6.5, 2.9)),
        (8, (0.0, -6.5, 2.0), (0.5, 6.5, 2.9)),
    ])

    sc.check_unique_indices()
    sc.write_recipe(HERE, RECIPE)
    sc.print_index_table()
    sc.save_blend(os.path.join(HERE, "greek_bath.blend"))


if __name__ == "__main__":
    sc.run_main(main)
