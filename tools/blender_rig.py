"""Run under Blender's Python (the `bpy` module): build a keyed, parented and skinned scene,
export it to glTF with Blender's own exporter, and write Blender's matrix_world and evaluated
skinned vertices at several frames to JSON, for tests/scene/imports/test_gltf.py.

    python tools/blender_rig.py OUT.glb OUT.json       # with a Python that has bpy
"""
import json, math, sys
import bpy

out_glb, out_json = sys.argv[-2], sys.argv[-1]
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps = 24
scene.frame_start, scene.frame_end = 0, 24

# keyed empties: a parent and a child
parent = bpy.data.objects.new("Parent", None)
scene.collection.objects.link(parent)
child = bpy.data.objects.new("Child", None)
scene.collection.objects.link(child)
child.parent = parent
child.location = (0.0, 1.0, 0.5)
for frame, loc, rot in ((0, (0, 0, 0), (0, 0, 0)), (12, (1, 0.5, 0.2), (0.3, 0.2, 1.0)), (24, (2, -0.5, 0), (0.0, 0.8, 2.0))):
    parent.location, parent.rotation_euler = loc, rot
    parent.keyframe_insert("location", frame=frame)
    parent.keyframe_insert("rotation_euler", frame=frame)
for frame, rot in ((0, (0, 0, 0)), (24, (1.2, 0, 0))):
    child.rotation_euler = rot
    child.keyframe_insert("rotation_euler", frame=frame)

# an armature of two bones and a mesh skinned to it (vertex groups + armature modifier)
arm_data = bpy.data.armatures.new("Rig")
rig = bpy.data.objects.new("Rig", arm_data)
scene.collection.objects.link(rig)
bpy.context.view_layer.objects.active = rig
bpy.ops.object.mode_set(mode="EDIT")
b1 = arm_data.edit_bones.new("Lower")
b1.head, b1.tail = (0, 0, 0), (0, 0, 1)
b2 = arm_data.edit_bones.new("Upper")
b2.head, b2.tail = (0, 0, 1), (0, 0, 2)
b2.parent = b1
bpy.ops.object.mode_set(mode="OBJECT")
verts = [(x, y, z * 0.25) for z in range(9) for x, y in ((-0.2, -0.2), (0.2, -0.2), (0.2, 0.2), (-0.2, 0.2))]
faces = [(r * 4 + i, r * 4 + (i + 1) % 4, (r + 1) * 4 + (i + 1) % 4, (r + 1) * 4 + i) for r in range(8) for i in range(4)]
mesh = bpy.data.meshes.new("Tube")
mesh.from_pydata(verts, [], faces)
tube = bpy.data.objects.new("Tube", mesh)
scene.collection.objects.link(tube)
tube.parent = rig
lower, upper = tube.vertex_groups.new(name="Lower"), tube.vertex_groups.new(name="Upper")
for v, (_, _, z) in enumerate(verts):
    w = min(max((z - 0.5) / 1.0, 0.0), 1.0)
    if w < 1:
        lower.add([v], 1 - w, "REPLACE")
    if w > 0:
        upper.add([v], w, "REPLACE")
tube.modifiers.new("Armature", "ARMATURE").object = rig
rig.location = (0.5, 0, 0)
for frame, a1, a2 in ((0, 0.0, 0.0), (10, 0.4, -0.6), (24, -0.3, 0.9)):
    for name, angle in (("Lower", a1), ("Upper", a2)):
        pb = rig.pose.bones[name]
        pb.rotation_mode = "XYZ"
        pb.rotation_euler = (angle, 0.0, angle / 2)
        pb.keyframe_insert("rotation_euler", frame=frame)

bpy.ops.export_scene.gltf(filepath=out_glb, export_format="GLB", export_animations=True, export_yup=True, export_force_sampling=True, export_animation_mode="SCENE")
result = {"frames": {}}
for frame in (0, 5, 10, 17, 24):
    scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = tube.evaluated_get(depsgraph)
    m = ev.matrix_world
    result["frames"][frame] = {
        "Parent": [list(r) for r in parent.matrix_world],
        "Child": [list(r) for r in child.matrix_world],
        "Tube": [list(m @ v.co) for v in ev.to_mesh().vertices],
    }
json.dump(result, open(out_json, "w"))
