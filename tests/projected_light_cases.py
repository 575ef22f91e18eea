"""Emitters that project images, one per case, for tests/test_projected_lights.py and for
measuring Mitsuba's values at POINTS (which that test holds). Paths are relative to
tracer/scenes/mitsuba."""

SPOT = ('<emitter type="spot"><rgb name="intensity" value="6, 5, 4"/><float name="cutoff_angle" value="28"/>'
        '<float name="beam_width" value="18"/><transform name="to_world"><lookat origin="-2.2, 3.0, 1.2" '
        'target="-1.2, 0, -0.4" up="0, 1, 0"/></transform>{texture}</emitter>')
CASES = {
    "spot_bilinear": SPOT.format(texture='<texture type="bitmap" name="texture"><string name="filename" '
                                 'value="textures/ramp.exr"/></texture>'),
    "spot_nearest_png": SPOT.format(texture='<texture type="bitmap" name="texture"><string name="filename" '
                                    'value="textures/tiles.png"/><string name="filter_type" value="nearest"/>'
                                    '</texture>'),
    "projector_scaled": ('<emitter type="projector"><float name="fov" value="40"/>'
                         '<float name="scale" value="2.5"/>'
                         '<transform name="to_world"><scale value="1.5"/><lookat origin="2.0, 2.4, 2.5" '
                         'target="0.9, 1.2, -1.5" up="0.2, 1, 0"/></transform><texture type="bitmap" '
                         'name="irradiance"><string name="filename" value="textures/tiles.png"/></texture>'
                         '</emitter>'),
    "projector_constant_fov_y": ('<emitter type="projector"><float name="fov" value="30"/>'
                                 '<string name="fov_axis" value="y"/><rgb name="irradiance" value="0.3, 0.6, 0.9"/>'
                                 '<transform '
                                 'name="to_world"><lookat origin="0.5, 4.0, 1.0" target="0.3, 0, 1.2" '
                                 'up="0, 0, -1"/></transform></emitter>'),
    "projector_focal_length": ('<emitter type="projector"><string name="focal_length" value="35mm"/><texture '
                               'type="bitmap" name="irradiance"><string name="filename" '
                               'value="textures/ramp.exr"/></texture><transform name="to_world">'
                               '<rotate y="1" angle="20"/><translate '
                               'z="3"/></transform></emitter>'),
}
# Points on the floor and the wall of tracer/scenes/mitsuba/projected_lights.xml, and beyond.
POINTS = [(-1.17, 0.0, -0.42), (-1.5, 0.0, -0.1), (-0.8, 0.0, -0.9), (0.9, 1.2, -1.5), (1.3, 1.5, -1.5),
          (0.4, 0.9, -1.5), (0.3, 0.0, 1.2), (0.6, 0.0, 0.9), (2.5, 0.0, 1.0), (0.4, 0.3, 6.5)]
