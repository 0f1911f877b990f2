"""Build the pool-caustics truth scene (issue 14): a pool floor lit by a high Sun, seen
straight down by an orthographic camera (so a pixel is a fixed size on the floor:
ORTHO_SCALE / width metres). The water surface (a displaced grid, material ``Water``)
is in the .blend but disabled for rendering: libfx's voronoi_caustics paints the
pattern on the floor (material ``Pool_Floor``). ``apply_truth()`` enables the water as
refractive glass (IOR 1.33), invisible to the camera, and turns Cycles' refractive
caustics on, with manifold next-event estimation (MNEE: the Sun a caustics light, the
water a caster, the floor a receiver) so a sun's caustics converge at few samples (the
ground truth, tests/bench/truth_caustics.py), and with two corrections that make Cycles'
light transport physical here (measured, docs/accuracy_truth.md#pool-caustics-voronoi_caustics):
the world is not sampled as a light (Cycles' MNEE scales a sun's caustic by the number of
lights it samples: 2x with the sky), and the water's refraction carries the radiance factor
n^2 (Cycles' refraction leaves it out: a floor under flat water got T / n^2 of the sun, not
the transmittance T that flux conservation gives).

    blender -b --factory-startup --python blend_scenes/truth_caustics/make_truth_caustics.py

Writes truth_caustics_pool.blend. The floor at z = -1.2 m, the water at z = 0 displaced by a
Clouds texture (noise size WAVE_SIZE m, amplitude WAVE_HEIGHT m).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402

import scene_common as sc  # noqa: E402

HERE = sc.script_dir(__file__)
RESOLUTION = (480, 270)
SAMPLES = 32
ORTHO_SCALE = 4.0
DEPTH = 1.2
WAVE_SIZE = 0.35
WAVE_HEIGHT = 0.05
WATER_IOR = 1.33
GRID = 12                       # water grid faces per side (6 m), each subdivided 16x16

RECIPE = {
    "version": 1,
    "quality": "final",
    "effects": [
        # params_version 3 (issue 27) with interior 0 and warp 0: the Greek bath's look, as measured before
        {"effect": "voronoi_caustics", "enabled": True, "params_version": 3,
         "params": {"mode": "physical", "points": 196, "tile_size": 3.0, "strength": 0.8, "line_width": 0.12,
                    "speed": 2.0, "interior": 0.0, "warp": 0.0},
         "mask": {"material": "Pool_Floor"}},
    ],
}


def water_grid(bm, size=6.0, n=GRID):
    vs = [[bm.verts.new((-size / 2 + size * i / n, -size / 2 + size * j / n, 0.0)) for i in range(n + 1)]
          for j in range(n + 1)]
    for j in range(n):
        for i in range(n):
            bm.faces.new((vs[j][i], vs[j][i + 1], vs[j + 1][i + 1], vs[j + 1][i]))


def main():
    scene = sc.reset_file()
    scene.name = "TruthCaustics"
    sc.render_settings(scene, samples=SAMPLES)
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.frame_start = scene.frame_end = 1
    sc.sky_world("Sky_TruthCaustics", strength=0.3)
    floor = sc.principled_material("Pool_Floor", (0.55, 0.7, 0.75), 1, roughness=0.8, specular=0.2)
    sc.mesh_object("Pool_Floor", lambda bm: sc.bm_box_minmax(bm, (-4, -4, -DEPTH - 0.2), (4, 4, -DEPTH)), floor, 1)
    water = bpy.data.materials.new("Water")
    water.pass_index = 2
    water.use_nodes = True
    nt = water.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    glass = nt.nodes.new("ShaderNodeBsdfGlass")
    sc.sharp_bsdf(glass)
    glass.inputs["IOR"].default_value = WATER_IOR
    glass.inputs["Color"].default_value = (1, 1, 1, 1)
    nt.links.new(glass.outputs[0], out.inputs["Surface"])
    obj = sc.mesh_object("Water", water_grid, water, 2, smooth=True)
    sub = obj.modifiers.new("Subdivide", 'SUBSURF')   # kept live: the .blend stays small
    sub.subdivision_type = 'SIMPLE'
    sub.levels = sub.render_levels = 4
    tex = bpy.data.textures.new("Waves", 'CLOUDS')
    tex.noise_scale = WAVE_SIZE
    tex.noise_basis = 'BLENDER_ORIGINAL'
    tex.noise_depth = 1
    disp = obj.modifiers.new("Waves", 'DISPLACE')
    disp.texture = tex
    disp.strength = WAVE_HEIGHT
    disp.mid_level = 0.5
    disp.direction = 'Z'
    disp.texture_coords = 'GLOBAL'
    obj.hide_render = True          # the input: no water (libfx paints the caustics)
    obj.visible_camera = False
    sun = sc.add_sun("Sun", sc.direction_from_angles(30.0, 70.0), strength=4.0, color=(1.0, 0.97, 0.9),
                     angle_deg=1.0)
    cam = sc.add_camera("Camera", lens=50.0)
    cam.data.type = 'ORTHO'
    cam.data.ortho_scale = ORTHO_SCALE
    cam.location = (0.0, 0.0, 4.0)
    cam.rotation_euler = (0.0, 0.0, 0.0)
    sun.name = "Sun"
    sc.check_unique_indices()
    sc.write_recipe(HERE, RECIPE)
    sc.save_blend(os.path.join(HERE, "truth_caustics_pool.blend"))


def physical_water(mat, ior=WATER_IOR):
    """The water's interface as Cycles' sharp Glass (a Fresnel mix of a sharp refraction and
    a sharp reflection), with the radiance factor of refraction that Cycles leaves out:
    radiance entering a medium of index n from air is n^2 times brighter (L / n^2 is
    invariant), so a path that leaves the water upwards (the interface seen from below)
    carries n^2 T, one that enters it 1 / n^2 T. Reflection is unchanged."""
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    fresnel = nt.nodes.new("ShaderNodeFresnel")
    fresnel.inputs["IOR"].default_value = ior
    refr = nt.nodes.new("ShaderNodeBsdfRefraction")
    refr.inputs["IOR"].default_value = ior
    refl = nt.nodes.new("ShaderNodeBsdfGlossy")
    for node in (refr, refl):
        sc.sharp_bsdf(node)
        node.inputs["Color"].default_value = (1, 1, 1, 1)
    back = nt.nodes.new("ShaderNodeNewGeometry")
    k = nt.nodes.new("ShaderNodeMath")          # n^2 seen from below, 1 / n^2 from above
    k.operation = 'MULTIPLY_ADD'
    nt.links.new(back.outputs["Backfacing"], k.inputs[0])
    k.inputs[1].default_value = ior * ior - 1.0 / (ior * ior)
    k.inputs[2].default_value = 1.0 / (ior * ior)
    nt.links.new(k.outputs[0], refr.inputs["Color"])
    mix = nt.nodes.new("ShaderNodeMixShader")   # the Fresnel node takes 1 / ior from below
    nt.links.new(fresnel.outputs[0], mix.inputs[0])
    nt.links.new(refr.outputs[0], mix.inputs[1])
    nt.links.new(refl.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])


def apply_truth(scene=None):
    """The ground truth: the water refracts the Sun onto the floor. Never saved.

    Two corrections of Cycles (3.4, 4.3 and 5.2 alike; measured with flat water, where the
    floor must get the Fresnel transmittance T of the sun's light, 0.980 at 20 deg):
    - the world is not sampled as a light: Cycles' MNEE divides a sun's caustic by the
      light-selection probability twice, so with the sky as a second light the caustic
      came out 2x (3 lights: 3x); the sky still lights the floor through the rays the
      floor's BSDF sends (a smooth gradient: little noise);
    - the water's refraction carries n^2 (physical_water): without it the floor got T / n^2
      (0.554 at n 1.33; 0.825 at 1.1, 0.370 at 1.6, as measured).
    Before them the two errors nearly cancelled: the floor got 2 T / n^2 = 1.108 of the
    sun's light in air, 1.13x the physical T."""
    scene = scene or bpy.context.scene
    w = bpy.data.objects["Water"]
    physical_water(bpy.data.materials["Water"])
    if scene.world is not None:
        scene.world.cycles.sampling_method = 'NONE'
    w.hide_render = False
    w.visible_camera = False
    cy = scene.cycles
    cy.caustics_refractive = True
    cy.caustics_reflective = False
    cy.transmission_bounces = 8
    cy.max_bounces = 8
    cy.sample_clamp_indirect = 0.0
    cy.blur_glossy = 0.0
    # MNEE (Blender 3.2+): caster, receiver and light flags
    if hasattr(w.cycles, "is_caustics_caster"):
        w.cycles.is_caustics_caster = True
        bpy.data.objects["Pool_Floor"].cycles.is_caustics_receiver = True
        bpy.data.objects["Sun"].data.cycles.is_caustics_light = True


if __name__ == "__main__":
    sc.run_main(main)
