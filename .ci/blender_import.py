# Import a glTF file into an empty Blender scene and print what came in as one JSON line
# prefixed "FURROW_JSON ": mesh objects with their shape keys (names, slider ranges) and
# materials, and every action with the data paths it animates.
# Usage: blender -b --factory-startup --python .ci/blender_import.py -- FILE.glb
import json
import sys

import bpy
import numpy

# Debian's Blender 3.4 importer uses numpy.bool, which numpy 1.24 (Debian bookworm) removed.
if not hasattr(numpy, "bool"):
    numpy.bool = bool

path = sys.argv[sys.argv.index("--") + 1]
bpy.ops.wm.read_factory_settings(use_empty=True)
error = None
try:
    bpy.ops.import_scene.gltf(filepath=path)
except Exception as e:  # the importer's refusal is the result
    error = str(e)
objects = []
for o in bpy.data.objects:
    if o.type != "MESH":
        continue
    keys = o.data.shape_keys
    objects.append({
        "name": o.name,
        "vertices": len(o.data.vertices),
        "shape_keys": [k.name for k in keys.key_blocks] if keys else [],
        "slider_min": [k.slider_min for k in keys.key_blocks] if keys else [],
        "materials": [m.name for m in o.data.materials if m],
        "uv_layers": [u.name for u in o.data.uv_layers],
    })
actions = [{"name": a.name, "fcurves": sorted({f.data_path for f in a.fcurves})}
           for a in bpy.data.actions]
print("FURROW_JSON " + json.dumps({"error": error, "objects": objects, "actions": actions}))
