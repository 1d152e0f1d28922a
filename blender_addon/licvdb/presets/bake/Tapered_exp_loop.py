# licvdb bake preset: A seamless 24-frame loop of tapered streamlets (oriented exp kernel, bright head downstream), seeded where the flow is faster than a quarter of its top speed, lines only.
import bpy
s = bpy.context.scene.licvdb_bake

s.length = 24.0
s.upsample = 2
s.kernel = 'exp'
s.decay = 0.95
s.seed = 1
s.input_type = 'spots'
s.spot_spacing = 14.0
s.spot_radius = 1.2
s.halo_scale = 2.0
s.roi_scalar = 'speed'
s.roi_range = (0.25, 1.0)
s.roi_relative = True
s.roi_mode = 'pre'
s.color_scalar = 'speed'
s.colormap = 'inferno'
s.loop_frames = 24
s.look_set = True
s.look = 'LINES'
s.look_brightness = 1.5
s.look_absorption = 0.3
s.look_halo_strength = 1.5
