"""Every numeric tolerance of plantgen's geometry, named once: the tolerance object ``tol``.

The bottom layer: this module imports nothing from plantgen. A threshold the code needs in
two places (or in numpy and in GLSL) is a field here, with what it guards and its unit;
two thresholds that merely share a value but guard different things are two fields.

Units: "relative" fields multiply a size named in their description (a row's radius or
length, a model's size, a ray's squared length); "world units" fields are lengths in the
skeleton's coordinates; the rest are dimensionless (sines, cosines, rises per unit of
axial height).

GLSL programs see the fields in :data:`GLSL_FIELDS` as macros ``TOL_<FIELD>`` (for
example ``TOL_RECENTER_PARALLEL``): :meth:`Tolerances.glsl_defines`, which the shader
loader (``plantgen.gl.shaders``) adds to every program. Their values are written with
``repr`` (``1e-06``), which a GLSL compiler reads as the same float32 as the literal
``1e-6``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Tolerances", "tol", "GLSL_FIELDS"]


@dataclass(frozen=True)
class Tolerances:
    """The named tolerances (see the module docstring); use the shared instance ``tol``."""

    # ------------------------------------------------------------------ float64 guards
    tiny: float = 1e-300
    """Floor of a float64 divisor or norm (any unit): ``x / max(x, tiny)`` stays finite
    where ``x`` underflows to 0, and a vector shorter than this has no direction. Far below
    any length a model has, so it changes no result that is not degenerate."""

    max_coordinate: float = 1e9
    """World units: the largest magnitude a skeleton's coordinate or radius (and a scene's
    position, a camera's eye) may have. Beyond it squares and products of lengths leave
    float32's range on the GPU and lose float64's precision on the CPU, so a model that
    reaches it (``F(1e308)``, ``!(1e308)``, a scale of 1e308) is refused, never drawn with
    inf or NaN coordinates."""

    zero_length: float = 1e-12
    """Relative (to a row's size: its radius or its length): a length below this counts as
    zero. Gives a zero-length segment a length, finds a cone closing to a point on a
    cutting plane (its normal (8) falls back to the cone's), floors the relief radius and
    generator length that tilt relief normals, and is the slack of the planes-crossing
    screen."""

    parallel: float = 1e-12
    """Dimensionless: a sine or cosine (or ``1 + cos``) below this counts as zero, so two
    unit directions this close to parallel (perpendicular, opposite) are treated as exactly
    so: a camera's up and view direction, a half-turn of the texture frame, a side branch
    perpendicular to or along its parent."""

    # ------------------------------------------------------------------ cutting planes
    generator_rise: float = 1e-12
    """Dimensionless (per unit of axial height): a generator ``a + k·e`` that rises less
    than this towards a cutting plane (``n·a + k·(n·e)``) does not meet it. Floors that
    rise in the axial extent of the bounding pyramids (numpy and GLSL) and marks a row
    whose planes do not cut every generator."""

    section_rise: float = 1e-9
    """Dimensionless (per unit of axial height): where the steepest generator rises less
    than this towards a plane, the section estimates give up on it: section points fall
    back to the axis end and the planes-crossing screen takes the spread as unbounded."""

    plane_tilt_cos: float = 1e-3
    """Dimensionless: floor of a cutting plane's ``n·axis`` (the cosine of its tilt from
    the axis) where the bounds and the bounding pyramids divide by it (numpy and GLSL)."""

    section_reach_cos: float = 0.05
    """Dimensionless: floor of ``cos θ - |k|·sin θ`` (θ a plane's tilt, k the slope) in
    :func:`plantgen.geometry.skeletons.frusta.frusta_bounds`: an elliptical cut reaches at most
    1/0.05 = 20 radii from where its plane crosses the axis."""

    pyramid_grazing: float = 0.05
    """Relative (to the smaller ``n·axis`` of a row's planes, floored at
    ``plane_tilt_cos``): an edge of the bounding pyramid meeting a plane with a smaller
    rise is grazing, and the row's pyramid uses planes perpendicular to the axis at the
    frustum's axial extent instead (numpy and GLSL)."""

    pyramid_pad: float = 1e-6
    """Relative (to the row's length plus its largest radius): the GPU pyramid grows by
    this besides ``hull_padding`` so that float32 rounding of its corners loses no pixel."""

    ribbon_margin: float = 1.0 / 64.0
    """Relative and in pixels: coverage anti-aliasing's screen quad of a thin row
    (``raycast.glsl``'s THIN_RIBBON) reaches this fraction of its width and this many
    pixels more beyond the bound of the row's projected radius (second-order terms of the
    perspective, float32 rounding)."""

    # ------------------------------------------------------------------ skinning
    same_length: float = 1e-9
    """Relative (to the larger of the two): two lengths of one row closer than this are
    equal. A joint whose two skeleton radii differ by more is a radius step (capped on both
    sides); the two planes of a row closer than this along a generator cross."""

    radius_step: float = 0.05
    """Relative (to the larger radius): a joint whose radii differ by more is a modelled
    radius step, left out of the seam mismatch and of seam fitting (§2.2)."""

    ellipse_margin: float = 1e-3
    """Dimensionless: a joint plane whose ``n·axis`` is within this of the cone's
    half-angle sine does not cut the cone in an ellipse; the joint becomes a knuckle."""

    runaway: float = 1e100
    """Relative (to the mean joint radius): clip of where a joint's two boundary lines
    cross (nearly parallel lines); the construction fades such crossings out anyway."""

    seam_radius_change: float = 0.25
    """Relative (to the skeleton's radius): closing a seam moves a continuing child's base
    radius by about r·(k_c² - k_p²)/2 (``plantgen.geometry.skeletons.skin.seam_radii``); a joint that
    would move it by more than this (a short child tapering steeply next to its radius,
    whose generators must then touch a sphere nearly as large as the child) becomes a
    knuckle instead, which is closed at any taper."""

    joint_slack: float = 2.0
    """Units of rounding (2^-24 in float32, the GPU's; the dtype's half epsilon in the
    reference): a lateral hit counts as between a row's planes up to
    ``joint_slack``·u·(|base| + h) beyond a plane it shares with a continuing neighbour
    (|base|: the base's distance from the render origin). The plane test of a row runs
    relative to its base, rounded at that size, and at a thin joint far from its base
    (r = 1e-4 h, seen from 8 r) both rows could reject the front hit: the slab where both
    accept closes that gap; the seams are closed, so the two cones agree in it. Open ends
    (caps) get no slack."""

    facing_min: float = 0.05
    """Dimensionless: where the interpolated normal (8) makes a cosine below this with the
    direction to the eye on a surface that faces the eye (the inside of a bend seen from
    outside), it is bent towards the true normal instead of being negated
    (``plantgen.geometry.skeletons.frusta.facing_normals``, GLSL ``facing_normal``): its cosine
    before normalising comes back to this, so after normalising it stays positive."""

    fan_length: float = 1e-9
    """Relative (to the radius): the length of a knuckle fan row, a slice with no extent
    along its axis."""

    short_row: float = 1e-6
    """Relative (to the larger radius): rows shorter than this are knuckle fan slices
    (whose length is ``fan_length`` radii), not segments."""

    count_rounding: float = 1e-9
    """Dimensionless: slack before rounding a ratio up to a count (knuckle slices per
    bend), so a ratio that is a whole number up to rounding is not rounded up."""

    frame_weak: float = 1e-6
    """Dimensionless (the reference direction is a unit vector): a transported texture
    reference direction shorter than this once its axial part is removed is rebuilt from
    a fixed helper direction."""

    joint_gap: float = 1e-9
    """Relative (to the model size, at least 1): a child segment may start this far from
    its parent's end (``Skeleton.validate``)."""

    joint_match: float = 1e-6
    """Relative (to a row's size, its radius but at least this much of its length): a row
    continues another found by shared planes only if its base lies this close to the
    other's top."""

    # ------------------------------------------------------------------ tessellation
    seam_snap: float = 1e-4
    """Relative (to the larger joint radius): two knuckle cut curves (or hinge points) of
    the mesh (``plantgen.geometry.meshes.mesh``) closer than this are one (C's vertices take P's
    positions); farther apart, a bridge joins them. A bridge narrower than this would be
    slivers (a nearly cylindrical P, tapering by 4e-5 of its radius, gave zero-area faces
    that welding folds); the snap moves C's cut by at most this, a tenth of the chord error
    of the finest level (m = 3: 1.2e-3 r)."""

    flat_bend: float = 1e-6
    """Radians: a knuckle of the mesh bending less than this is flat (no outer strips: P's
    top ring joins C's bottom ring directly, or both are capped at a radius step)."""

    # ------------------------------------------------------------------ leaf polygons
    polygon_area: float = 1e-12
    """Relative (to the square of an outline's extent, the extent floored at this many world
    units): a leaf outline's Newell vector (twice its area) below this has no normal (the
    least-squares plane's stands in), and an ear-clipping corner turning less (twice its
    triangle's area) is collinear and dropped (``plantgen.geometry.meshes.outlines``)."""

    outline_duplicate: float = 1e-9
    """Relative (to an outline's extent, floored as for ``polygon_area``): consecutive
    outline points (the last and the first included) closer than this are one vertex."""

    # ------------------------------------------------------------------ ray casting
    recenter_parallel: float = 1e-6
    """Relative (to D·D): a ray with ``D·D - (D·a)²`` below this runs along the axis;
    it is re-centred on the segment's middle (numpy reference and GLSL)."""

    triangle_grazing: float = 1e-12
    """Relative (to |e1|·|e2|·|d|): a ray whose Möller-Trumbore determinant is below this
    lies in a leaf triangle's plane and misses it (the scan's test and the GPU's
    traversal, shaders/bvh.glsl)."""

    box_pad: float = 1e-9
    """Relative (to a box's largest coordinate): the reference's slab-test boxes grow by
    this (and ``box_pad_floor``) so that rounding of the pyramid corners loses no ray."""

    box_pad_floor: float = 1e-12
    """World units: the slab-test boxes grow by at least this."""

    light_window_pad: float = 1e-9
    """World units: the light's shadow-map window grows by at least this on every side,
    so casters that are flat along a window axis still get a window of some extent."""

    behind_eye: float = 1e-9
    """Relative (to the row's corners' distance from the eye): a bounding-pyramid corner
    this close to the eye's plane, or behind it, puts its row in every screen tile."""

    relief_bisection: float = 1e-10
    """Relative (to the row's size, shell included): the reference's relief hits are
    bisected until the bracket is shorter than this."""

    shadow_normal: float = 1e-6
    """Dimensionless: floor of ``|n·light_forward|`` in the receiver-plane depth gradient
    of the shadow look-up (GLSL), so a normal perpendicular to the light stays finite."""

    tangent_floor_f32: float = 1e-20
    """World units (float32, GLSL): floor of the tangent lengths |∂P/∂u| and |∂P/∂v|
    that the relief gradient divides by."""

    parallax_grazing_cos: float = 1e-3
    """Dimensionless: floor of the view's cosine N·V on a facet in GS+POM's march (GLSL), so
    a facet seen edge-on marches at most 1/this shell thicknesses along its ray."""

    similarity: float = 1e-9
    """Dimensionless: how far a copy's turn (its placement's linear part over its uniform
    scale) may be from a rotation (largest entry of ``turnᵀ·turn - I``) for the GPU to
    keep it as a quaternion (:mod:`plantgen.gl.trace`); far below float32's rounding, so the
    quaternion loses nothing the 3x4 map would keep. A copy further from it (one that
    scales unevenly or shears) makes the scene keep full maps."""

    # ------------------------------------------------------------------ framing
    frame_extent: float = 1e-9
    """World units: the smallest extent a camera frames (a model of one point still
    gets a camera)."""

    frame_distance: float = 1e-6
    """World units: the smallest distance at which automatic framing puts the eye."""

    depth_far_pad: float = 1e-6
    """World units: the far distance of a depth range lies this far past the farthest
    point (besides the 5 % margin)."""

    near_far_ratio: float = 1e-5
    """Dimensionless: the near distance of a depth range stays above this times the far
    one, so the depth buffer keeps its precision."""

    def glsl_defines(self) -> dict[str, float]:
        """``TOL_<FIELD>`` -> value for every field of :data:`GLSL_FIELDS`."""
        return {f"TOL_{name.upper()}": float(getattr(self, name)) for name in GLSL_FIELDS}


#: The fields GLSL programs use, as macros ``TOL_<FIELD>``.
GLSL_FIELDS = ("facing_min", "generator_rise", "joint_slack", "plane_tilt_cos", "pyramid_grazing", "pyramid_pad",
               "ribbon_margin", "recenter_parallel", "shadow_normal", "triangle_grazing", "tangent_floor_f32",
               "parallax_grazing_cos")

#: The tolerances of plantgen.
tol = Tolerances()
