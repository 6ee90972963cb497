#!/usr/bin/env python3
"""Forward kinematics of a URDF, independent of drawcal (stdlib only:
xml.etree and math). Used by tests/engine/export.rs.

    python3 urdf_fk.py FILE.urdf BASE_LINK TIP_LINK < angles.txt

Each input line holds the angles (degrees) of the chain's moving joints
(revolute, continuous) from BASE_LINK to TIP_LINK, in chain order; each
output line is the TIP_LINK origin in the BASE_LINK frame, in millimetres.
"""
import math
import sys
import xml.etree.ElementTree as ET


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def origin(el):
    o = el.find("origin")
    xyz = [0.0, 0.0, 0.0]
    rpy = [0.0, 0.0, 0.0]
    if o is not None:
        if o.get("xyz"):
            xyz = [float(v) for v in o.get("xyz").split()]
        if o.get("rpy"):
            rpy = [float(v) for v in o.get("rpy").split()]
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    # URDF: fixed-axis roll, pitch, yaw: R = Rz(y) Ry(p) Rx(r)
    return [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr, xyz[0]],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr, xyz[1]],
        [-sp, cp * sr, cp * cr, xyz[2]],
        [0.0, 0.0, 0.0, 1.0],
    ]


def axis_rotation(axis, q):
    n = math.sqrt(sum(v * v for v in axis))
    x, y, z = (v / n for v in axis)
    c, s = math.cos(q), math.sin(q)
    t = 1 - c
    return [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y, 0.0],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x, 0.0],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]


def main():
    path, base, tip = sys.argv[1:4]
    robot = ET.parse(path).getroot()
    by_child = {j.find("child").get("link"): j for j in robot.findall("joint")}
    chain = []
    at = tip
    while at != base:
        j = by_child[at]
        chain.append(j)
        at = j.find("parent").get("link")
    chain.reverse()
    for line in sys.stdin:
        if not line.strip():
            continue
        q = [math.radians(float(v)) for v in line.split()]
        t = [[1.0 if i == k else 0.0 for k in range(4)] for i in range(4)]
        k = 0
        for j in chain:
            t = matmul(t, origin(j))
            if j.get("type") in ("revolute", "continuous"):
                ax = j.find("axis")
                axis = [float(v) for v in ax.get("xyz").split()] if ax is not None else [1.0, 0.0, 0.0]
                t = matmul(t, axis_rotation(axis, q[k]))
                k += 1
        if k != len(q):
            sys.exit(f"{len(q)} angles for {k} moving joints")
        print(" ".join(repr(1000.0 * t[i][3]) for i in range(3)))


if __name__ == "__main__":
    main()
