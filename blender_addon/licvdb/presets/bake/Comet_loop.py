# licvdb bake preset: A seamless 24-frame loop: spots travel downstream as comets (box kernel), in halos, seeded where the flow is faster than a quarter of its top speed, coloured by speed.
import bpy
s = bpy.context.scene.licvdb_bake

s.length = 20.0
s.upsample = 2
s.kernel = 'box'
s.decay = 0.9
s.seed = 1
s.input_type = 'spots'
s.spot_spacing = 14.0
s.spot_radius = 1.0
s.halo_scale = 2.0
s.roi_scalar = 'speed'
s.roi_range = (0.25, 1.0)
s.roi_relative = True
s.roi_mode = 'pre'
s.color_scalar = 'speed'
s.colormap = 'heated-object'
s.loop_frames = 24
s.look_set = True
s.look = 'HALOS'
s.look_brightness = 1.0
s.look_absorption = 0.3
s.look_halo_strength = 1.5
