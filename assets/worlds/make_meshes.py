#!/usr/bin/env python3
"""Writes the detailed meshes of the proxy-reality worlds (OBJ, metres, closed surfaces).

The twins approximate these objects with boxes, cylinders and capsules; the proxy worlds render
these meshes, so a twin rebuilt from their depth scans is genuinely approximate. Run from the
repository root after changing a shape: python3 assets/worlds/make_meshes.py
(standard library only; the OBJ files are committed, nothing is generated at build time).
"""
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


class Mesh:
    def __init__(self):
        self.v, self.f = [], []

    def add(self, other):
        base = len(self.v)
        self.v += other.v
        self.f += [tuple(i + base for i in face) for face in other.f]
        return self

    def moved(self, dx=0.0, dy=0.0, dz=0.0):
        m = Mesh()
        m.v = [(x + dx, y + dy, z + dz) for x, y, z in self.v]
        m.f = list(self.f)
        return m

    def write(self, path):
        with open(path, "w") as out:
            out.write("# written by assets/worlds/make_meshes.py\n")
            for x, y, z in self.v:
                out.write(f"v {x:.6f} {y:.6f} {z:.6f}\n")
            for a, b, c in self.f:
                out.write(f"f {a + 1} {b + 1} {c + 1}\n")


def lathe(profile, segments, phase=0.0, closed=False):
    """Surface of revolution about z of (r, z) points; outward normals when the profile runs
    counter-clockwise in the (r, z) half-plane (outer wall upward). Points with r = 0 are poles."""
    m = Mesh()
    rings = []
    for r, z in profile:
        if r == 0:
            rings.append([len(m.v)])
            m.v.append((0.0, 0.0, z))
            continue
        ring = []
        for k in range(segments):
            a = phase + 2 * math.pi * k / segments
            ring.append(len(m.v))
            m.v.append((r * math.cos(a), r * math.sin(a), z))
        rings.append(ring)
    pairs = list(zip(rings, rings[1:]))
    if closed:
        pairs.append((rings[-1], rings[0]))
    for lo, hi in pairs:
        for k in range(segments):
            k2 = (k + 1) % segments
            if len(lo) == 1:
                m.f.append((lo[0], hi[k2], hi[k]))
            elif len(hi) == 1:
                m.f.append((lo[k], lo[k2], hi[0]))
            else:
                m.f.append((lo[k], lo[k2], hi[k2]))
                m.f.append((lo[k], hi[k2], hi[k]))
    return outward(m)


def tube(path, radius, normal, segments=16):
    """A closed tube of circular section along a polyline lying in the plane with the given
    normal; capped at both ends."""
    m = Mesh()
    rings = []
    for i, p in enumerate(path):
        a = path[max(i - 1, 0)]
        b = path[min(i + 1, len(path) - 1)]
        t = [b[j] - a[j] for j in range(3)]
        n = math.sqrt(sum(c * c for c in t))
        t = [c / n for c in t]
        u = list(normal)  # the same section frame all along a planar path: no twist
        w = [t[1] * u[2] - t[2] * u[1], t[2] * u[0] - t[0] * u[2], t[0] * u[1] - t[1] * u[0]]
        ring = []
        for k in range(segments):
            ang = 2 * math.pi * k / segments
            ring.append(len(m.v))
            m.v.append(tuple(p[j] + radius * (math.cos(ang) * u[j] + math.sin(ang) * w[j]) for j in range(3)))
        rings.append(ring)
    for lo, hi in zip(rings, rings[1:]):
        for k in range(segments):
            k2 = (k + 1) % segments
            m.f.append((lo[k], hi[k], hi[k2]))
            m.f.append((lo[k], hi[k2], lo[k2]))
    for ring, p, flip in ((rings[0], path[0], True), (rings[-1], path[-1], False)):
        c = len(m.v)
        m.v.append(tuple(p))
        for k in range(segments):
            k2 = (k + 1) % segments
            m.f.append((c, ring[k2], ring[k]) if flip else (c, ring[k], ring[k2]))
    return outward(m)


def arc(center, radius, start, end, steps, plane="xz"):
    pts = []
    for i in range(steps + 1):
        a = start + (end - start) * i / steps
        c, s = radius * math.cos(a), radius * math.sin(a)
        if plane == "xz":
            pts.append((center[0] + c, center[1], center[2] + s))
        else:
            pts.append((center[0] + c, center[1] + s, center[2]))
    return pts


def pull_handle(length, depth, radius, bend):
    """A D-shaped pull: two standoffs from the panel (x = 0) out to x = -depth, joined by a bar
    along y, with rounded corners of radius `bend`."""
    half = length / 2
    path = [(0.0, -half, 0.0), (-(depth - bend), -half, 0.0)]
    path += arc((-(depth - bend), -half + bend, 0.0), bend, -math.pi / 2, -math.pi, 6, "xy")[1:]
    path += [(-depth, half - bend, 0.0)]
    path += arc((-(depth - bend), half - bend, 0.0), bend, math.pi, math.pi / 2, 6, "xy")[1:]
    path += [(0.0, half, 0.0)]
    return tube(path, radius, (0.0, 0.0, 1.0), 14)


def mug():
    """Hollow mug, 8 cm across, 9 cm tall, 4 mm walls, with a loop handle on +x."""
    R, H, t, b = 0.04, 0.09, 0.004, 0.006
    profile = [(0, 0.0), (R - 0.003, 0.0), (R, 0.003), (R, H), (R - t, H), (R - t, b), (0, b)]
    body = lathe(profile, 40).moved(dz=-H / 2)
    # Handle: a half loop in the xz plane from the wall at z = +-0.027 out to x = R + 0.028.
    loop = arc((R - 0.002, 0.0, 0.0), 0.027, -math.pi / 2, math.pi / 2, 16, "xz")
    handle = tube(loop, 0.0065, (0.0, 1.0, 0.0), 12)
    return body.add(handle)


def drawer_front():
    """The drawer's front panel with a 5 mm bevel all round (35 x 16 x 2 cm)."""
    hy, hz, hx, bev = 0.175, 0.08, 0.01, 0.005
    # A square-ish lathe with 4 segments gives a rectangle only for equal sides; build a box
    # with bevelled front edges from two rectangles instead.
    m = Mesh()
    back = [(hx, -hy, -hz), (hx, hy, -hz), (hx, hy, hz), (hx, -hy, hz)]
    mid = [(-hx + bev, -hy, -hz), (-hx + bev, hy, -hz), (-hx + bev, hy, hz), (-hx + bev, -hy, hz)]
    front = [(-hx, -hy + bev, -hz + bev), (-hx, hy - bev, -hz + bev), (-hx, hy - bev, hz - bev),
             (-hx, -hy + bev, hz - bev)]
    m.v = back + mid + front
    quads = []
    for k in range(4):
        k2 = (k + 1) % 4
        quads.append((k, k2, 4 + k2, 4 + k))          # sides: back ring to mid ring
        quads.append((4 + k, 4 + k2, 8 + k2, 8 + k))  # bevel: mid ring to front ring
    quads.append((0, 3, 2, 1))    # back face
    quads.append((8, 9, 10, 11))  # front face
    for a, b_, c, d in quads:
        m.f += [(a, b_, c), (a, c, d)]
    return fix_winding(m)


def fix_winding(m):
    """Orients every face outward for a convex-ish closed mesh (normal away from the centroid)."""
    cx = [sum(v[j] for v in m.v) / len(m.v) for j in range(3)]
    faces = []
    for a, b, c in m.f:
        pa, pb, pc = m.v[a], m.v[b], m.v[c]
        u = [pb[j] - pa[j] for j in range(3)]
        w = [pc[j] - pa[j] for j in range(3)]
        n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]
        centre = [(pa[j] + pb[j] + pc[j]) / 3 - cx[j] for j in range(3)]
        faces.append((a, b, c) if sum(n[j] * centre[j] for j in range(3)) >= 0 else (a, c, b))
    m.f = faces
    return m


def peg():
    """Square peg, 2.0 cm across, 9 cm long, 2 mm chamfer at the tip (lathe with 4 sides)."""
    half, L, ch = 0.01, 0.09, 0.002
    d = math.sqrt(2)  # lathe radius of a square of half-side h is h * sqrt(2)
    profile = [(0, -L / 2), ((half - ch) * d, -L / 2), (half * d, -L / 2 + ch), (half * d, L / 2),
               (0, L / 2)]
    return lathe(profile, 4, phase=math.pi / 4)


def hole_block():
    """6.3 cm square block, 4 cm tall, with a 2.3 cm square hole through it and a 2 mm chamfer at
    its mouth (a closed square ring, lathe with 4 sides)."""
    d = math.sqrt(2)
    inner, outer, H, ch = 0.0115, 0.0315, 0.04, 0.002
    profile = [(inner * d, -H / 2), (outer * d, -H / 2), (outer * d, H / 2),
               ((inner + ch) * d, H / 2), (inner * d, H / 2 - ch)]
    return lathe(profile, 4, phase=math.pi / 4, closed=True)


def pancake_half(top):
    """One half of a round pancake, 8.8 cm across and 1.1 cm thick, its rim rounded off (two
    halves so that the browned underside can be another colour from the top)."""
    r, h, bevel = 0.044, 0.0055, 0.003
    if top:
        profile = [(0, 0), (r, 0), (r, h - bevel), (r - bevel, h), (0, h)]
    else:
        profile = [(0, -h), (r - bevel, -h), (r, -h + bevel), (r, 0), (0, 0)]
    return outward(lathe(profile, 20))


def signed_volume(m):
    total = 0.0
    for a, b, c in m.f:
        pa, pb, pc = m.v[a], m.v[b], m.v[c]
        total += (pa[0] * (pb[1] * pc[2] - pb[2] * pc[1]) - pa[1] * (pb[0] * pc[2] - pb[2] * pc[0])
                  + pa[2] * (pb[0] * pc[1] - pb[1] * pc[0])) / 6.0
    return total


def outward(m):
    """Flips an inside-out closed surface."""
    if signed_volume(m) < 0:
        m.f = [(a, c, b) for a, b, c in m.f]
    return m


def write(world, name, mesh):
    path = os.path.join(HERE, world, "meshes", name + ".obj")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    mesh.write(path)
    print(path, len(mesh.v), "vertices", len(mesh.f), "faces", f"{signed_volume(mesh) * 1e6:.1f} cm3")


if __name__ == "__main__":
    write("open_drawer", "drawer_handle", pull_handle(0.12, 0.065, 0.0075, 0.01))
    write("open_drawer", "drawer_front", drawer_front())
    write("open_cabinet", "door_handle", pull_handle(0.125, 0.065, 0.0075, 0.012))
    write("mug_on_shelf", "mug", mug())
    write("peg_insertion", "peg", peg())
    write("peg_insertion", "hole_block", hole_block())
    write("spatula_flipping", "pancake_top", pancake_half(True))
    write("spatula_flipping", "pancake_bottom", pancake_half(False))
