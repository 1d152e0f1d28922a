"""The LIC look as a node tree, built by one pure function.

``build_lic_material(mat, grids, look)`` clears ``mat``'s node tree except its output, adds the
nodes for ``look`` and links them by socket name. Only the output's *Volume* socket is
connected: a Surface link on a volume object makes Cycles render its bounding box as an opaque
block (see docs/blender.md, "The look").

The look (Cycles and EEVEE):

* lines: emission = brightness × density × colour, plus a mild absorption from ``density`` so
  lines in front dim lines behind them;
* colour: the ``color`` grid, or the ``scalar`` grid through a colour ramp rebuilt from the
  bake's colormap (4× lighter in Cycles' memory than a vec3 grid), or white;
* halos (``look.mode == 'HALOS'``): a black absorbing shell, absorption from
  max(halo − density, 0) × halo strength, so a line passing behind another shows a gap on both
  sides of it, as in the reference raycaster.

Strengths are per unit length in Cycles, so they are scaled by 1 / voxel size: the same
settings give the same picture for any bake resolution or world scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from . import compat
from . import grids as G

#: Blender's colour ramp holds at most this many elements.
MAX_RAMP_ELEMENTS = 32


@dataclass
class Look:
    """Everything the node tree depends on (mirrors the panel's settings)."""

    mode: str = "LINES"  # 'LINES' | 'HALOS'
    brightness: float = 1.0  # emission of a line of full density, about 1 = white on black
    line_absorption: float = 0.3  # absorption of the lines themselves, same units as halo
    halo_strength: float = 1.5  # absorption per voxel of halo shell (× 1/voxel size)
    color_source: str = "AUTO"  # 'AUTO' | 'COLOR' | 'SCALAR' | 'WHITE'
    colormap: list = field(default_factory=list)  # [(pos, r, g, b)] sRGB, from the manifest
    voxel_size: float = 1.0  # world units of one output voxel (scales the strengths)
    halo_shell: float = 1.5  # output voxels from a line's edge to its halo's edge (see below)


def halo_shell_voxels(recipe: dict) -> float:
    """How far a line's halo reaches beyond the line, in output voxels, from a bake's recipe:
    spot radius × (halo_scale − 1) for spot inputs; 1.5 when the recipe does not say."""
    inp = (recipe or {}).get("input") or {}
    radii = inp.get("radii") or []
    scale = inp.get("halo_scale")
    if inp.get("type") == "spots" and radii and scale:
        return max(0.0, float(radii[0]) * (float(scale) - 1.0))
    return 1.5


def srgb_to_linear(c: float) -> float:
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def ramp_points(points, max_elements: int = MAX_RAMP_ELEMENTS) -> list:
    """Colormap control points [(pos, r, g, b)] in sRGB, thinned to at most ``max_elements``
    (keeping the ends), as scene-linear [(pos, (r, g, b, 1))] for a colour ramp."""
    pts = sorted(points)
    if len(pts) > max_elements:
        step = (len(pts) - 1) / (max_elements - 1)
        pts = [pts[round(i * step)] for i in range(max_elements)]
    return [(p[0], tuple(srgb_to_linear(v) for v in p[1:4]) + (1.0,)) for p in pts]


def resolve_color_source(look: Look, grids) -> str:
    """The colour source actually used: AUTO prefers the lighter ``scalar`` + ramp when the bake
    has a colormap, then ``color``; a source whose grid is missing falls back to white."""
    names = set(grids)
    src = look.color_source
    if src == "AUTO":
        if G.SCALAR in names and look.colormap:
            return "SCALAR"
        return "COLOR" if G.COLOR in names else "WHITE"
    if src == "SCALAR" and (G.SCALAR not in names or not look.colormap):
        return "WHITE"
    if src == "COLOR" and G.COLOR not in names:
        return "WHITE"
    return src


def _attribute(nodes, name: str, location):
    node = nodes.new("ShaderNodeAttribute")
    node.attribute_name = name
    node.attribute_type = "GEOMETRY"
    node.name = node.label = f"grid {name}"
    node.location = location
    return node


def _math(nodes, op: str, location, value=None, clamp=False, name=None):
    node = nodes.new("ShaderNodeMath")
    node.operation = op
    node.use_clamp = clamp
    if value is not None:
        node.inputs[1].default_value = value
    node.location = location
    if name:
        node.name = node.label = name
    return node


def build_lic_material(mat, grids, look: Look):
    """Rebuild ``mat``'s node tree for a bake with grids ``grids`` (names) and look ``look``.

    Returns a dict of the nodes a caller (or a test) may want: ``output``, ``emission``,
    ``absorption``, ``ramp`` (or None), ``halo_shell`` (or None).
    """
    tree = compat.ensure_node_tree(mat)
    nodes, links = tree.nodes, tree.links
    output = next((n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial"), None)
    for n in list(nodes):
        if output is None or n.name != output.name:
            nodes.remove(n)
    if output is None:
        output = nodes.new("ShaderNodeOutputMaterial")
    for link in list(links):
        links.remove(link)
    output.location = (900, 0)
    output.target = "ALL"

    grids = set(grids)
    inv_voxel = 1.0 / max(look.voxel_size, 1e-9)
    # Emission per voxel of path: a line a few voxels across shines about ``brightness``
    # after its own absorption.
    emit_scale = look.brightness * inv_voxel
    halos = look.mode == "HALOS" and G.HALO in grids
    if halos:
        # Every line also sits behind its own halo shell, which the reference raycaster does not
        # count (its first halo segment is composited normally): scale the emission up by the
        # shell's transmittance so lines keep their brightness and only lines behind others dim.
        emit_scale *= math.exp(look.halo_strength * look.halo_shell)

    density = _attribute(nodes, G.DENSITY, (-700, 200))

    # Colour.
    source = resolve_color_source(look, grids)
    ramp = None
    if source == "COLOR":
        color_socket = _attribute(nodes, G.COLOR, (-700, 450)).outputs["Color"]
    elif source == "SCALAR":
        scalar = _attribute(nodes, G.SCALAR, (-700, 450))
        ramp = nodes.new("ShaderNodeValToRGB")
        ramp.name = ramp.label = "colormap"
        ramp.location = (-450, 450)
        cr = ramp.color_ramp
        cr.color_mode = "RGB"
        cr.interpolation = "LINEAR"
        pts = ramp_points(look.colormap)
        while len(cr.elements) > 1:
            cr.elements.remove(cr.elements[-1])
        cr.elements[0].position = pts[0][0]
        cr.elements[0].color = pts[0][1]
        for pos, col in pts[1:]:
            cr.elements.new(pos).color = col
        links.new(scalar.outputs["Fac"], ramp.inputs["Fac"])
        color_socket = ramp.outputs["Color"]
    else:
        color_socket = None

    # Emission from density.
    emission = nodes.new("ShaderNodeEmission")
    emission.name = emission.label = "line emission"
    emission.location = (300, 250)
    strength = _math(nodes, "MULTIPLY", (-100, 200), emit_scale, name="line brightness")
    links.new(density.outputs["Fac"], strength.inputs[0])
    links.new(strength.outputs["Value"], emission.inputs["Strength"])
    if color_socket is not None:
        links.new(color_socket, emission.inputs["Color"])
    else:
        emission.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)

    # Absorption: lines, and the halo shell.
    absorption = nodes.new("ShaderNodeVolumeAbsorption")
    absorption.name = absorption.label = "black absorption"
    absorption.location = (300, -100)
    absorption.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    line_abs = _math(nodes, "MULTIPLY", (-100, 0), look.line_absorption * inv_voxel, name="line absorption")
    links.new(density.outputs["Fac"], line_abs.inputs[0])
    halo_shell = None
    if halos:
        halo = _attribute(nodes, G.HALO, (-700, -200))
        shell = _math(nodes, "SUBTRACT", (-450, -200), clamp=True, name="halo minus line")
        links.new(halo.outputs["Fac"], shell.inputs[0])
        links.new(density.outputs["Fac"], shell.inputs[1])
        halo_shell = _math(nodes, "MULTIPLY", (-250, -200), look.halo_strength * inv_voxel, name="halo strength")
        links.new(shell.outputs["Value"], halo_shell.inputs[0])
        total = _math(nodes, "ADD", (50, -100), name="absorption")
        links.new(line_abs.outputs["Value"], total.inputs[0])
        links.new(halo_shell.outputs["Value"], total.inputs[1])
        links.new(total.outputs["Value"], absorption.inputs["Density"])
    else:
        links.new(line_abs.outputs["Value"], absorption.inputs["Density"])

    add = nodes.new("ShaderNodeAddShader")
    add.location = (600, 100)
    links.new(emission.outputs["Emission"], add.inputs[0])
    links.new(absorption.outputs["Volume"], add.inputs[1])
    links.new(add.outputs["Shader"], output.inputs["Volume"])
    return {"output": output, "emission": emission, "absorption": absorption, "ramp": ramp,
            "halo_shell": halo_shell, "color_source": source}


def setup_render(scene, step_rate: float = 0.5):
    """Render settings that suit LIC volumes: Cycles, black world, a volume step fine enough for
    thin lines, no denoising where this Blender has no OpenImageDenoise.

    Where Cycles has the *Biased* volume option (5.0+) it is turned on: the thin-line look is
    made for ray marching at ``step_rate`` (half a voxel), which 5.0's default null scattering
    ignores (see compat.has_volume_biased and docs/blender.md)."""
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    if compat.has_volume_biased(scene):
        cycles.volume_biased = True
    cycles.volume_step_rate = step_rate
    cycles.volume_preview_step_rate = step_rate
    cycles.volume_max_steps = max(cycles.volume_max_steps, 1024)
    cycles.volume_bounces = 0
    if not oidn_available():
        cycles.use_denoising = False
        cycles.use_preview_denoising = False
    world = scene.world
    if world is None:
        import bpy

        world = scene.world = bpy.data.worlds.new("licvdb black")
    tree = compat.ensure_node_tree(world)
    bg = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground"), None) if tree else None
    if bg is not None:
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        bg.inputs["Strength"].default_value = 0.0
    world.color = (0.0, 0.0, 0.0)
    scene.view_settings.view_transform = "Standard"


def oidn_available() -> bool:
    """True if this Blender's Cycles was built with OpenImageDenoise (Debian's 3.4 is not)."""
    try:
        import _cycles
    except ImportError:
        return False
    return bool(getattr(_cycles, "with_openimagedenoise", False))
