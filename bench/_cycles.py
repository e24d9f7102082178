"""Blender Cycles as the benches' peer (bench_equal_error.py, bench_movers.py): the pieces
of a Cycles scene both build inside a Python with `bpy`, our Y-up turned to Blender's Z-up."""

from __future__ import annotations

from typing import Any


def blender(v: Any) -> tuple[float, float, float]:
    """A point or direction of ours (Y up) in Blender's frame (Z up)."""
    return (float(v[0]), float(-v[2]), float(v[1]))


def cycles_scene(threads: int, resolution: tuple[int, int], fps: float, shutter: float, max_bounces: int) -> Any:
    """An empty scene rendered by Cycles on the CPU with `threads` threads at `resolution`,
    motion blur over `shutter` of a frame, persistent data (warm frames keep the scene and
    its BVH), `max_bounces`, no clamping, the Standard view transform, 32-bit EXR output."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.render.threads_mode = "FIXED"
    scene.render.threads = threads
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.render.fps, scene.render.fps_base = fps, 1.0
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = shutter
    scene.render.use_persistent_data = True
    scene.cycles.max_bounces = max_bounces
    scene.cycles.sample_clamp_direct = 0.0
    scene.cycles.sample_clamp_indirect = 0.0
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    return scene


def diffuse(name: str, rgb: Any) -> Any:
    """A Cycles material: a diffuse BSDF of colour `rgb`."""
    import bpy

    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (*rgb, 1.0)
    mat.node_tree.links.new(bsdf.outputs["BSDF"], nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    return mat
