"""The grids of a licvdb bake that the add-on reads, by role.

They are rows of licvdb's output-grid table (lic/composite/OutputGrids.h, listed by
``licvdb help --json`` as "grids", with what the add-on does with each);
tests/blender/test_choices.py checks these names and types against it.
"""

DENSITY = "density"    # float: emission and absorption of the lines
HALO = "halo"          # float: the black shell behind lines (look Halos)
VELOCITY = "velocity"  # vec3s: the volume's velocity grid (motion blur)
COLOR = "color"        # vec3s: the lines' colour
SCALAR = "scalar"      # float: the lines' colour through a ramp of the bake's colormap

# name -> value type, as the bake writes it
USED = {DENSITY: "float", HALO: "float", VELOCITY: "vec3s", COLOR: "vec3s", SCALAR: "float"}
