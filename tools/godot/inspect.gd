# Load an imported scene in Godot 3.2 and print one line "TREEGEN_JSON {...}" describing what the
# engine made of it: node tree, skeletons, mesh surfaces (vertex count, normals, UV range, material),
# animation players and whether playing the animation moves any bone.
# Usage: godot3-server --path PROJECT -s res://inspect.gd [--scene=res://x.glb]
extends SceneTree

const EPS = 1e-4

func _initialize():
	var scene_path = "res://x.glb"
	for a in OS.get_cmdline_args():
		if a.begins_with("--scene="):
			scene_path = a.substr(8, a.length() - 8)
	var out = {"scene": scene_path, "loaded": false}
	var t0 = OS.get_ticks_msec()
	var packed = load(scene_path)
	if packed == null:
		out["reason"] = "load() returned null"
		_emit(out)
		return
	out["resource_type"] = packed.get_class()
	if not packed is PackedScene:
		out["reason"] = "not a PackedScene"
		_emit(out)
		return
	var inst = packed.instance()
	if inst == null:
		out["reason"] = "instance() returned null"
		_emit(out)
		return
	get_root().add_child(inst)
	out["loaded"] = true
	out["load_ms"] = OS.get_ticks_msec() - t0

	var nodes = []
	var skeletons = []
	var meshes = []
	var players = []
	_walk(inst, -1, nodes, skeletons, meshes, players)
	out["nodes"] = nodes
	out["skeletons"] = []
	for s in skeletons:
		out["skeletons"].append(_skeleton_info(inst, s))
	out["mesh_instances"] = []
	for m in meshes:
		out["mesh_instances"].append(_mesh_info(inst, m))
	out["animation_players"] = []
	for p in players:
		out["animation_players"].append(_player_info(inst, p, skeletons))
	_emit(out)

func _emit(out):
	print("TREEGEN_JSON " + JSON.print(out))
	quit()

func _walk(n, parent, nodes, skeletons, meshes, players):
	var idx = nodes.size()
	nodes.append({"name": n.name, "type": n.get_class(), "parent": parent})
	if n is Skeleton:
		skeletons.append(n)
	if n is MeshInstance:
		meshes.append(n)
	if n is AnimationPlayer:
		players.append(n)
	for c in n.get_children():
		_walk(c, idx, nodes, skeletons, meshes, players)

func _skeleton_info(root, s):
	var roots = 0
	var names = []
	for i in range(s.get_bone_count()):
		if s.get_bone_parent(i) < 0:
			roots += 1
		if i < 8:
			names.append(s.get_bone_name(i))
	return {"path": str(root.get_path_to(s)), "bone_count": s.get_bone_count(),
		"root_bones": roots, "first_bones": names}

func _mesh_info(root, mi):
	var info = {"path": str(root.get_path_to(mi)), "skeleton": str(mi.skeleton), "surfaces": []}
	var skel = null
	if mi.skeleton != NodePath("") and mi.has_node(mi.skeleton):
		skel = mi.get_node(mi.skeleton)
	info["skeleton_found"] = skel != null and skel is Skeleton
	if mi.skin != null:
		info["skin_binds"] = mi.skin.get_bind_count()
	var mesh = mi.mesh
	if mesh == null:
		return info
	info["mesh_type"] = mesh.get_class()
	for i in range(mesh.get_surface_count()):
		var arrays = mesh.surface_get_arrays(i)
		var surf = {}
		var verts = arrays[Mesh.ARRAY_VERTEX]
		surf["vertices"] = verts.size() if verts != null else 0
		var normals = arrays[Mesh.ARRAY_NORMAL]
		surf["has_normal"] = normals != null and normals.size() > 0
		if surf["has_normal"]:
			var zero = 0
			for n in normals:
				if n.length() < 1e-6:
					zero += 1
			surf["zero_normals"] = zero
		var uv = arrays[Mesh.ARRAY_TEX_UV]
		surf["has_uv"] = uv != null and uv.size() > 0
		if surf["has_uv"]:
			var lo = Vector2(uv[0])
			var hi = Vector2(uv[0])
			for p in uv:
				lo.x = min(lo.x, p.x)
				lo.y = min(lo.y, p.y)
				hi.x = max(hi.x, p.x)
				hi.y = max(hi.y, p.y)
			surf["uv_min"] = [lo.x, lo.y]
			surf["uv_max"] = [hi.x, hi.y]
		var bones = arrays[Mesh.ARRAY_BONES]
		surf["has_bones"] = bones != null and bones.size() > 0
		if surf["has_bones"]:
			var bmax = 0
			for b in bones:
				bmax = max(bmax, b)
			surf["bone_index_max"] = bmax
		var mat = mi.get_surface_material(i)
		if mat == null:
			mat = mesh.surface_get_material(i)
		surf["material"] = _material_info(mat)
		info["surfaces"].append(surf)
	return info

func _material_info(mat):
	if mat == null:
		return null
	var m = {"name": mat.resource_name, "type": mat.get_class()}
	if mat is SpatialMaterial:
		m["albedo_texture"] = mat.albedo_texture != null
		m["normal_texture"] = mat.normal_enabled and mat.normal_texture != null
		m["albedo_color"] = [mat.albedo_color.r, mat.albedo_color.g, mat.albedo_color.b, mat.albedo_color.a]
		m["transparent"] = mat.flags_transparent
		m["alpha_scissor"] = mat.params_use_alpha_scissor
		m["alpha_scissor_threshold"] = mat.params_alpha_scissor_threshold
		m["cull_mode"] = ["back", "front", "disabled"][mat.params_cull_mode]
	return m

func _poses(skeletons):
	var out = []
	for s in skeletons:
		var local = []
		var world = []
		for i in range(s.get_bone_count()):
			local.append(s.get_bone_pose(i))
			world.append(s.get_bone_global_pose(i))
		out.append([local, world])
	return out

func _xform_diff(a, b):
	var d = 0.0
	for k in range(3):
		d = max(d, _vmax((a.basis[k] - b.basis[k]).abs()))
	d = max(d, _vmax((a.origin - b.origin).abs()))
	return d

func _vmax(v):
	return max(v.x, max(v.y, v.z))

func _pose_diff(pa, pb):
	# -> [bones moved (local), max local diff, max global diff]
	var moved = 0
	var dl = 0.0
	var dg = 0.0
	for k in range(pa.size()):
		for i in range(pa[k][0].size()):
			var d = _xform_diff(pa[k][0][i], pb[k][0][i])
			if d > EPS:
				moved += 1
			dl = max(dl, d)
			dg = max(dg, _xform_diff(pa[k][1][i], pb[k][1][i]))
	return [moved, dl, dg]

func _player_info(root, p, skeletons):
	var info = {"path": str(root.get_path_to(p)), "animations": []}
	for name in p.get_animation_list():
		var a = p.get_animation(name)
		var ai = {"name": name, "length": a.length, "tracks": a.get_track_count(), "loop": a.loop}
		var resolved = 0
		var keys_max = 0
		for t in range(a.get_track_count()):
			keys_max = max(keys_max, a.track_get_key_count(t))
			var np = a.track_get_path(t)
			var base = NodePath(str(np).split(":")[0])
			if p.get_node(p.root_node).has_node(base):
				resolved += 1
		ai["tracks_resolved"] = resolved
		ai["keys_max"] = keys_max
		if a.length > 0:
			a.loop = false  # so that seek(length) lands on the last key instead of wrapping to 0
			p.play(name)
			p.seek(0.0, true)
			var p0 = _poses(skeletons)
			p.seek(a.length * 0.37, true)
			var p1 = _poses(skeletons)
			p.seek(a.length, true)
			var p2 = _poses(skeletons)
			var mv = _pose_diff(p0, p1)
			ai["sample_times"] = [0.0, a.length * 0.37]
			ai["bones_moved"] = mv[0]
			ai["max_local_change"] = mv[1]
			ai["max_global_change"] = mv[2]
			var lp = _pose_diff(p0, p2)
			ai["loop_max_diff"] = max(lp[1], lp[2])
			ai["loop_closes"] = lp[1] <= EPS and lp[2] <= EPS
			p.stop()
			a.loop = ai["loop"]
		info["animations"].append(ai)
	return info
