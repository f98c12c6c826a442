"""Write the camera sidecar (and optionally render) for `server import blender`.

Blender does not store the camera in its EXR files, so this script writes one
JSON sidecar, `cameras.json`, describing the active camera at every frame of
the scene's range: its camera-to-world matrix, lens, sensor, sensor fit,
shift, clip range and the frame time. With `--render` it also sets up the
passes the importer needs (Combined, Depth, Vector, Object Index; motion blur
off, since Blender only offers the Vector pass without it) and renders the
frames as multilayer OpenEXR next to the sidecar.

Usage (Blender 3.x or 4.x, any engine that writes Z and Vector):

    blender -b scene.blend -P tools/blender/framegen_export.py -- --out DIR [--render]

then

    cargo run --release -p server -- import blender DIR --out DUMP

Objects whose transform is animated get pass index 1 (unless they already
have one), so the Object Index pass marks them as dynamic: the importer turns
it into the dump's `mask` buffer and checks motion vectors only on pixels
outside it.
"""

import argparse
import json
import os
import sys

import bpy

SIDECAR = "cameras.json"
FORMAT = "framegen-blender-cameras"
VERSION = 1


def camera_entry(scene, frame):
    """The sidecar's record of the active camera at `frame` (already set)."""
    cam = scene.camera
    if cam is None:
        raise RuntimeError("the scene has no active camera")
    data = cam.data
    render = scene.render
    return {
        "frame": frame,
        "time": frame * render.fps_base / render.fps,
        "file": os.path.basename(render.frame_path(frame=frame)),
        "resolution": [
            int(render.resolution_x * render.resolution_percentage / 100),
            int(render.resolution_y * render.resolution_percentage / 100),
        ],
        "pixel_aspect": [render.pixel_aspect_x, render.pixel_aspect_y],
        "camera": {
            "type": data.type,
            # Row-major 4x4, Blender's world axes (Z up).
            "matrix_world": [list(row) for row in cam.matrix_world],
            "lens": data.lens,
            "sensor_width": data.sensor_width,
            "sensor_height": data.sensor_height,
            "sensor_fit": data.sensor_fit,
            "shift_x": data.shift_x,
            "shift_y": data.shift_y,
            "clip_start": data.clip_start,
            "clip_end": data.clip_end,
        },
    }


def animated_objects(scene):
    """Objects with an animation action (they move on their own)."""
    return [
        obj
        for obj in scene.objects
        if obj.animation_data is not None and obj.animation_data.action is not None
    ]


def mark_animated(scene):
    """Give animated objects without a pass index one no other object uses,
    so the Object Index pass tells them apart."""
    fresh = max([obj.pass_index for obj in scene.objects] + [0]) + 1
    for obj in animated_objects(scene):
        if obj.pass_index == 0:
            obj.pass_index = fresh


def animated_pass_indices(scene):
    """The pass indices the importer masks, or None when an animated object
    has none (index 0 is every unindexed object): the importer then derives
    the mask from the motion. A static object sharing an animated object's
    index is masked with it."""
    indices = sorted({obj.pass_index for obj in animated_objects(scene)})
    if 0 in indices:
        return None
    return indices


def setup_render(scene, out):
    """Passes and output format the importer reads."""
    layer = bpy.context.view_layer
    layer.use_pass_combined = True
    layer.use_pass_z = True
    layer.use_pass_vector = True
    layer.use_pass_object_index = True
    scene.render.use_motion_blur = False
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"
    scene.render.filepath = os.path.join(os.path.abspath(out), "")
    mark_animated(scene)


def export(scene, out, render=False):
    os.makedirs(out, exist_ok=True)
    if render:
        setup_render(scene, out)
        bpy.ops.render.render(animation=True)
    frames = []
    for frame in range(scene.frame_start, scene.frame_end + 1, scene.frame_step):
        scene.frame_set(frame)
        frames.append(camera_entry(scene, frame))
    sidecar = {
        "format": FORMAT,
        "version": VERSION,
        "blender_version": bpy.app.version_string,
        "engine": scene.render.engine,
        "fps": scene.render.fps / scene.render.fps_base,
        "view_layer": bpy.context.view_layer.name,
        "frames": frames,
    }
    listed = animated_pass_indices(scene)
    if listed is not None:
        sidecar["animated_pass_indices"] = listed
    with open(os.path.join(out, SIDECAR), "w") as f:
        json.dump(sidecar, f, indent=1)
        f.write("\n")


def main(argv):
    parser = argparse.ArgumentParser(prog="framegen_export.py")
    parser.add_argument("--out", required=True, help="directory for cameras.json (and the EXRs)")
    parser.add_argument("--render", action="store_true", help="also render the frames")
    args = parser.parse_args(argv)
    export(bpy.context.scene, args.out, render=args.render)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else [])
