# licvdb bake preset: Dense LIC (noise) only where the flow is faster than 40 % of its top speed, cut at the region's edge.
import bpy
s = bpy.context.scene.licvdb_bake

s.length = 12.0
s.upsample = 2
s.kernel = 'box'
s.decay = 0.9
s.seed = 1
s.input_type = 'noise'
s.spot_spacing = 12.0
s.spot_radius = 1.0
s.halo_scale = 2.0
s.roi_scalar = 'speed'
s.roi_range = (0.4, 1.0)
s.roi_relative = True
s.roi_mode = 'post'
s.color_scalar = 'speed'
s.colormap = 'magma'
s.loop_frames = 1
s.look_set = True
s.look = 'LINES'
s.look_brightness = 0.6
s.look_absorption = 1.0
s.look_halo_strength = 1.5
