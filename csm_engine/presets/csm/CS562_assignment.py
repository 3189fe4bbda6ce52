# CSM preset: The CS562 assignment's method, so every control it asks for visibly acts: 3
# cascades of 2048/1024/512 texels, the course's hybrid splits (Lambda 0.5 over clip
# start .. far clip, Fit to View off), each pixel's cascade chosen by its view depth
# with a 2 m blend band before each split, plain 3x3 PCF (Sharpen 1: the kernel's
# own ramp, so Radius visibly widens the penumbra), the occluder margin from the
# scene bounds, stabilized cascades.
import bpy
csm = bpy.context.scene.csm

csm.cascade_count = 3
csm.resolution = 2048
csm.equal_resolution = False
csm.split_scheme = 'HYBRID'
csm.split_lambda = 0.5
csm.fitted_split_lambda = 0.9
csm.manual_splits = (0.1, 0.3, 0.6)
csm.fit_to_visible = False
csm.shadow_distance = 0.0
csm.stabilize = True
csm.fade_out = True
csm.fade_fraction = 0.1
csm.cascade_selection = 'DEPTH'
csm.blend_band = 2.0
csm.shadow_filter = 'PCF'
csm.pcf_radius = 1
csm.pcf_sharpen = 1.0
csm.pcf_pattern = 'GRID'
csm.depth_bias = 1.0
csm.slope_bias = 0.5
csm.normal_offset = 0.0
csm.cull_front_faces = False
csm.occluder_margin_auto = True
csm.occluder_margin = 100.0
csm.render_samples = 1
csm.fxaa = True
csm.ambient_occlusion = True
csm.ao_distance = 0.2
csm.ao_strength = 1.0
