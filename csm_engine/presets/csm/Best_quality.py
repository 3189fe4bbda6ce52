# CSM preset: The add-on's defaults, chosen with the ground-truth tool: cascades fitted
# to the visible depth, each pixel reading the finest map that holds it, sharpened 3x3
# PCF, ambient occlusion and FXAA.
import bpy
csm = bpy.context.scene.csm

csm.cascade_count = 3
csm.resolution = 2048
csm.equal_resolution = False
csm.split_scheme = 'HYBRID'
csm.split_lambda = 0.5
csm.fitted_split_lambda = 0.9
csm.manual_splits = (0.1, 0.3, 0.6)
csm.fit_to_visible = True
csm.shadow_distance = 0.0
csm.stabilize = True
csm.fade_out = True
csm.fade_fraction = 0.1
csm.cascade_selection = 'MAP'
csm.blend_band = 2.0
csm.shadow_filter = 'PCF'
csm.pcf_radius = 1
csm.pcf_sharpen = 3.0
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
