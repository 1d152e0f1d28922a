"""Rendering a scene to a numpy image inside Blender (background mode has no Render Result pixels)."""

import os

import bpy
import numpy as np


def render_luminance(path, size=64, samples=16):
    """Render the current scene with Cycles on the CPU to ``path`` and return its luminance as a
    (rows, cols) array, row 0 at the bottom (Blender's pixel order). ``.png``: display-encoded
    (Standard view); ``.exr``: scene-linear."""
    scene = bpy.context.scene
    r = scene.render
    r.resolution_x = r.resolution_y = size
    r.resolution_percentage = 100
    r.filepath = str(path)
    if str(path).endswith(".exr"):
        r.image_settings.file_format = "OPEN_EXR"
        r.image_settings.color_depth = "32"
    else:
        r.image_settings.file_format = "PNG"
    r.image_settings.color_mode = "RGB"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    bpy.ops.render.render(write_still=True)
    assert os.path.isfile(path), f"render did not write {path}"
    img = bpy.data.images.load(str(path), check_existing=False)
    try:
        px = np.array(img.pixels[:], dtype=np.float32).reshape(size, size, img.channels)
    finally:
        bpy.data.images.remove(img)
    return 0.2126 * px[..., 0] + 0.7152 * px[..., 1] + 0.0722 * px[..., 2]


def ortho_camera_looking_down(center, width, height=3.0):
    """An orthographic camera above ``center`` looking down −z, framing ``width`` world units."""
    cam_data = bpy.data.cameras.new("licvdb test camera")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = width
    cam_data.clip_start, cam_data.clip_end = 0.01, 100.0
    cam = bpy.data.objects.new("licvdb test camera", cam_data)
    bpy.context.collection.objects.link(cam)
    cam.location = (center[0], center[1], center[2] + height)
    cam.rotation_euler = (0.0, 0.0, 0.0)
    bpy.context.scene.camera = cam
    return cam
