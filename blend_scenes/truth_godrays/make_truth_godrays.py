"""Build the god-rays truth scene (issue 14): a closed room with one window (a cross of
mullions) in its back wall, a low Sun seen through the window; no volume in the .blend
(libfx's god_rays adds the shafts). ``apply_truth()`` fills the room with a homogeneous
Volume Scatter (the ground truth, tests/bench/truth_godrays.py).

    blender -b --factory-startup --python blend_scenes/truth_godrays/make_truth_godrays.py

Writes truth_godrays_window.blend. Room x in [-4, 4], y in [0, 10], z in [0, 4]; window x in
[-1.2, 1.2], z in [2.3, 3.7] in the back wall (y = 10); the camera at (0, 1, 1.3) looks
at the window; the Sun 12 deg up straight ahead (azimuth 0), its disc drawn by the
world for camera rays (scene_common.sky_world), so it is on screen through the window.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402

import scene_common as sc  # noqa: E402

HERE = sc.script_dir(__file__)
RESOLUTION = (480, 270)
SAMPLES = 32
RX, RY, RZ = 4.0, 10.0, 4.0
WIN = (-1.2, 1.2, 2.3, 3.7)           # x0, x1, z0, z1
SUN_AZ, SUN_EL = 4.0, 12.0
VOLUME_DENSITY = 0.03
VOLUME_ANISOTROPY = 0.6

RECIPE = {
    "version": 1,
    "quality": "final",
    "effects": [
        {"effect": "god_rays", "enabled": True,
         "params": {"light": "Sun", "occlusion": "sky", "threshold": 0.9, "knee": 0.5, "max_source": 6.0,
                    "decay": 0.975, "density": 0.95, "weight": 1.0, "exposure": 0.006}},
    ],
}


def main():
    scene = sc.reset_file()
    scene.name = "TruthGodRays"
    sc.render_settings(scene, samples=SAMPLES)
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.frame_start = scene.frame_end = 1
    sun_dir = sc.direction_from_angles(SUN_AZ, SUN_EL)
    sc.sky_world("Sky_TruthGodRays", strength=1.0, sun_dir=sun_dir, sun_strength=60.0, sun_size_deg=3.0,
                 glow_strength=4.0, glow_size_deg=15.0)
    floor = sc.principled_material(
        "Floor_Wood", (0.45, 0.3, 0.18), 1, roughness=0.6,
        texture=lambda nt, b, c, k: sc.tex_wood(nt, b, c, k, scale=2.0))
    wall = sc.principled_material(
        "Wall_Plaster", (0.7, 0.66, 0.6), 2, roughness=0.9,
        texture=lambda nt, b, c, k: sc.tex_noise(nt, b, c, k, scale=1.5, contrast=0.9))
    frame = sc.principled_material("Window_Frame", (0.2, 0.15, 0.1), 3, roughness=0.5)
    crate = sc.principled_material("Crate", (0.6, 0.4, 0.2), 4, roughness=0.7)
    t = 0.25
    x0, x1, z0, z1 = WIN
    sc.mesh_object("Floor", lambda bm: sc.bm_box_minmax(bm, (-RX - t, -t, -t), (RX + t, RY + t, 0)), floor, 1)

    def walls(bm):
        sc.bm_box_minmax(bm, (-RX - t, -t, 0), (-RX, RY, RZ))
        sc.bm_box_minmax(bm, (RX, -t, 0), (RX + t, RY, RZ))
        sc.bm_box_minmax(bm, (-RX, -t, 0), (RX, 0, RZ))
        sc.bm_box_minmax(bm, (-RX - t, -t, RZ), (RX + t, RY + t, RZ + t))
        # the back wall around the window
        sc.bm_box_minmax(bm, (-RX - t, RY, 0), (RX + t, RY + t, z0))
        sc.bm_box_minmax(bm, (-RX - t, RY, z1), (RX + t, RY + t, RZ))
        sc.bm_box_minmax(bm, (-RX - t, RY, z0), (x0, RY + t, z1))
        sc.bm_box_minmax(bm, (x1, RY, z0), (RX + t, RY + t, z1))
    sc.mesh_object("Walls", walls, wall, 2)

    def mullions(bm):
        xm, zm = (x0 + x1) / 2, (z0 + z1) / 2
        sc.bm_box_minmax(bm, (xm - 0.05, RY, z0), (xm + 0.05, RY + 0.1, z1))
        sc.bm_box_minmax(bm, (x0, RY, zm - 0.05), (x1, RY + 0.1, zm + 0.05))
    sc.mesh_object("Window_Mullions", mullions, frame, 3)
    sc.mesh_object("Crates", lambda bm: (sc.bm_box(bm, (-2.2, 6.0, 0.5), (1.0, 1.0, 1.0), rot_deg=(0, 0, 15)),
                                         sc.bm_box(bm, (2.0, 7.5, 0.4), (0.8, 0.8, 0.8), rot_deg=(0, 0, -20))),
                   crate, 4)
    sc.add_sun("Sun", sun_dir, strength=6.0, color=(1.0, 0.92, 0.75), angle_deg=1.0)
    cam = sc.add_camera("Camera", lens=22.0)
    cam.location = (0.0, 1.0, 1.3)
    cam.rotation_euler = sc.look_at_euler(cam.location, (0.0, RY, 2.6))
    sc.check_unique_indices()
    sc.write_recipe(HERE, RECIPE)
    sc.save_blend(os.path.join(HERE, "truth_godrays_window.blend"))


def apply_truth(scene=None):
    """The ground truth: the room filled with a homogeneous Volume Scatter (density
    VOLUME_DENSITY per metre, anisotropy VOLUME_ANISOTROPY: forward scattering), single
    scattering (no volume bounce). Never saved."""
    scene = scene or bpy.context.scene
    m = bpy.data.materials.new("Room_Air")
    m.use_nodes = True
    nt = m.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    vs = nt.nodes.new("ShaderNodeVolumeScatter")
    vs.inputs["Density"].default_value = VOLUME_DENSITY
    vs.inputs["Anisotropy"].default_value = VOLUME_ANISOTROPY
    nt.links.new(vs.outputs[0], out.inputs["Volume"])
    e = 0.02
    obj = sc.mesh_object("Room_Air", lambda bm: sc.bm_box_minmax(bm, (-RX + e, e, e), (RX - e, RY - e, RZ - e)),
                         m, 0)
    obj.visible_shadow = True
    scene.cycles.volume_bounces = 0


if __name__ == "__main__":
    sc.run_main(main)
