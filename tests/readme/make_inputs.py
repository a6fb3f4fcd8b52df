#!/usr/bin/env python3
"""Write the input files that README.md's examples name, into the current directory.

Standard library only (no numpy): NPY is a magic string, a version, a header
length and a Python-dict header padded to a multiple of 64 bytes, then the raw
little-endian values; PNG is a signature and IHDR/IDAT/IEND chunks, each with
its CRC, the pixel rows filter-0 and zlib-compressed.

Sizes are small so that a debug build runs every example in seconds, but large
enough for every point the README uses (road.png is 512 x 512, the masks and
costs 256 x 256).
"""
import json
import math
import struct
import zlib


def write_npy(path, shape, dtype, values):
    """dtype: 'f8' or 'u1'; values: a flat sequence in C order."""
    descr = {"f8": "<f8", "u1": "|u1"}[dtype]
    shape_text = "(%s)" % (", ".join(str(n) for n in shape) + ("," if len(shape) == 1 else ""))
    header = "{'descr': '%s', 'fortran_order': False, 'shape': %s, }" % (descr, shape_text)
    # magic (6) + version (2) + length (2) + header + '\n', padded to 64 bytes
    pad = 64 - (10 + len(header) + 1) % 64
    header = header + " " * (pad % 64) + "\n"
    if dtype == "f8":
        data = struct.pack("<%dd" % len(values), *values)
    else:
        data = bytes(values)
    with open(path, "wb") as f:
        f.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1") + data)


def write_png(path, height, width, pixel):
    """8-bit grey PNG; pixel(r, c) -> 0..255."""
    raw = bytearray()
    for r in range(height):
        raw.append(0)  # filter type: none
        raw.extend(pixel(r, c) for c in range(width))

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(bytes(raw), 6))
                + chunk(b"IEND", b""))


def grid(n, m, value):
    return [value(r, c) for r in range(n) for c in range(m)]


def road_pixel(r, c):
    # A bright road along row 10 and on to (400, 300), over a textured ground.
    on_road = abs(r - 10) <= 4 or (r >= 10 and abs((c - 20) * 390 - (r - 10) * 280) <= 5 * 480)
    if on_road:
        return 200
    return 60 + (r * 7 + c * 13) % 40


def cells_pixel(r, c):
    # Two bright discs (cells) on a dark background.
    if (r - 40) ** 2 + (c - 40) ** 2 <= 20 ** 2 or (r - 80) ** 2 + (c - 90) ** 2 <= 25 ** 2:
        return 220
    return 30


def shaded_pixel(r, c, n=64, radius=40.0):
    # A sphere cap lit from the camera: I = 1 / sqrt(1 + |grad z|^2) = cos(normal, view).
    y, x = r - (n - 1) / 2, c - (n - 1) / 2
    d2 = x * x + y * y
    if d2 >= radius * radius:
        return 255  # flat ground around it
    return max(1, round(255 * math.sqrt(radius * radius - d2) / radius))


def ridges_pixel(r, c):
    # Two ridges from (10, 6) to (10, 34): a dim straight one (0.6) along row
    # 10 and a bright one (1) bulging down to row 24, on a dark ground.
    if abs(r - 10) <= 1 and 6 <= c <= 34:
        return 153
    if r >= 10 and abs(math.hypot(r - 10, c - 20) - 14) <= 1:
        return 255
    return 0


def icosphere(levels):
    t = (1 + 5 ** 0.5) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
             (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [tuple(x / math.sqrt(sum(v * v for v in p)) for x in p) for p in verts]
    for _ in range(levels):
        cache = {}

        def middle(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                p = [(verts[a][i] + verts[b][i]) / 2 for i in range(3)]
                norm = math.sqrt(sum(x * x for x in p))
                verts.append(tuple(x / norm for x in p))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return verts, faces


def main():
    write_png("road.png", 512, 512, road_pixel)
    write_png("cells.png", 128, 128, cells_pixel)
    write_png("shaded.png", 64, 64, shaded_pixel)
    write_png("ridges.png", 64, 64, ridges_pixel)
    # A square with a square hole, for domain meshing.
    write_png("shape.png", 100, 100,
              lambda r, c: 255 if 10 <= r < 90 and 10 <= c < 90 and not (40 <= r < 60 and 40 <= c < 60) else 0)

    # phi: a circle of radius 150.2 on a 512 x 512 grid, negative inside.
    phi = grid(512, 512, lambda r, c: math.hypot(r - 255.5, c - 255.5) - 150.2)
    write_npy("phi.npy", (512, 512), "f8", phi)
    write_npy("PHI.npy", (512, 512), "f8", phi)

    # A cost (256 x 256): 1, and 0.05 on a circle of radius 12 around (20, 20),
    # the contour that grid.group's example key points lie on.
    cost = grid(256, 256, lambda r, c: 0.05 if abs(math.hypot(r - 20, c - 20) - 12) <= 1 else 1.0)
    write_npy("W.npy", (256, 256), "f8", cost)
    write_npy("COST.npy", (256, 256), "f8", cost)

    # A mask (256 x 256): a disc in the middle (an obstacle for the planner, a shape for the EDT).
    mask = grid(256, 256, lambda r, c: 1 if (r - 128) ** 2 + (c - 128) ** 2 <= 40 ** 2 else 0)
    write_npy("mask.npy", (256, 256), "u1", mask)
    write_npy("M.npy", (256, 256), "u1", mask)
    # A region as a source (256 x 256): a small square.
    write_npy("region.npy", (256, 256), "u1", grid(256, 256, lambda r, c: 1 if 60 <= r < 70 and 60 <= c < 70 else 0))

    # Cost-gradient targets (rows of [row, column]) and their observed travel times.
    write_npy("Y.npy", (2, 2), "f8", [200.0, 100.0, 50.5, 220.25])
    write_npy("T.npy", (2,), "f8", [230.0, 240.0])

    # Perceptual grouping: four key points on the circle of W.npy and one clutter point.
    with open("K.json", "w") as f:
        json.dump({"key_points": [[20, 8], [32, 20], [20, 32], [8, 20], [50, 50]]}, f)

    # Tomography data: the README's curl example's (two sources, two receivers).
    with open("data.json", "w") as f:
        json.dump({"sources": [{"point": [0, 0]}, {"point": [0, 63]}],
                   "receivers": [{"point": [63, 0]}, {"point": [63, 63]}],
                   "times": [[71.2, 95.3], [95.3, 71.2]]}, f)

    # A small closed surface (an icosphere: 162 vertices, 320 faces) as ASCII PLY.
    verts, faces = icosphere(2)
    with open("bunny.ply", "w") as f:
        f.write("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                "property float z\nelement face %d\nproperty list uchar int vertex_indices\n"
                "end_header\n" % (len(verts), len(faces)))
        for v in verts:
            f.write("%.6f %.6f %.6f\n" % v)
        for face in faces:
            f.write("3 %d %d %d\n" % face)


if __name__ == "__main__":
    main()
