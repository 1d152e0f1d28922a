# licvdb bake preset: A seamless 24-frame loop of tapered streamlets (oriented exp kernel, bright head downstream), lines only.
import bpy
s = bpy.context.scene.licvdb_bake

s.length = 20.0
s.upsample = 2
s.kernel = 'exp'
s.decay = 0.85
s.seed = 1
s.input_type = 'spots'
s.spot_spacing = 10.0
s.spot_radius = 1.2
s.halo_scale = 2.0
s.roi_scalar = 'NONE'
s.roi_range = (0.5, 1.0)
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
