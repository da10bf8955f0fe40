"""Conical frusta: the skinned skeleton, one row per segment (Bhagvat et al. 2009, §2).

Contract (float64 on the CPU; converted to float32 only at upload):

==============  ==========  ==============================================================
``base``        (n, 3) f8   C1, the axis point where the cone's radius is ``r1``
``axis``        (n, 3) f8   unit axis direction, base towards top
``length``      (n,) f8     h, the axis length; the top point is C2 = base + h·axis
``r1``, ``r2``  (n,) f8     radii at C1 and C2; the cone is r(y) = r1 + k·y with
                            k = (r2 - r1)/h (slope form: no special case for cylinders
                            or cones closing to a point); hits with r(y) < 0 are rejected
``plane_lo``    (n, 4) f8   lower cutting plane (nx, ny, nz, d): unit normal pointing
                            roughly along ``axis``; inside iff n·x - d >= 0
``plane_hi``    (n, 4) f8   upper cutting plane, same orientation; inside iff n·x - d <= 0.
                            A continuing child's ``plane_lo`` equals its parent's
                            ``plane_hi`` bit for bit (the joint's shared plane)
``ref_dir``     (n, 3) f8   unit vector ⟂ axis, the u = 0 direction (rotation-minimising
                            frame carried along each chain)
``u_offset``    (n,) f8     added to u (§2.3) so u is continuous across joints
``twist``       (n,) f8     twist angle θ in turns; u gains v·twist
``material``    (n,) i4     index into ``material_names``
``shell``       (n,) f8     relief shell thickness (0: no relief on this segment)
``segment``     (n,) i8     index of the skeleton segment this row came from (sharp-bend
                            splitting can give one skeleton segment several rows)
==============  ==========  ==============================================================

u and v of a surface point P (equations (6)–(7)), with frame b = axis × ref_dir::

    u = atan2((P - C1)·b, (P - C1)·ref_dir) / 2π + u_offset + v·twist     (mod 1)
    v = |P - P_l| / |P_u - P_l|

where P_l and P_u are the intersections of the generator through P (direction
axis + k·e_r, e_r the unit radial direction of P) with the lower and upper planes.
The interpolated normal (8) is normalize((1 - v)·N_l + v·N_u), N_l = normalize(P_l - C1),
N_u = normalize(P_u - C2).
"""
