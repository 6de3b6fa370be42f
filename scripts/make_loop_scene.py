#!/usr/bin/env python3
"""Writes config/scenes/loop.yaml: a corridor ring around a closed block (12 x 10 m outside,
2 m wide), walked once round and on past the start (42 m of camera path, 1,500
frames). It is the loop-closure scene: the walk comes back to walls it saw at the start. The
YAML is committed; this script documents how it was made.

Usage: scripts/make_loop_scene.py > config/scenes/loop.yaml
"""
import math

from scene_parts import plane, rect, waypoints

FRAMES = 1500
OUTER_X, OUTER_Y, H = 12.0, 10.0, 2.6
WIDTH = 2.0  # corridor width: the block spans [WIDTH, OUTER - WIDTH] each way
EYE, LOOK_Z, LOOK_AHEAD = 1.5, 0.9, 2.5

# Posters along the outer walls, each its own picture, so that places differ:
# (wall, u of the left edge, seed, height of the lower edge).
POSTERS = [("south", 2.5, 31, 1.2), ("south", 7.5, 32, 1.2), ("east", 3.0, 33, 1.2),
           ("east", 7.0, 34, 1.2), ("north", 3.5, 35, 1.2), ("north", 8.5, 36, 1.2),
           ("west", 2.5, 37, 1.2), ("west", 6.5, 38, 1.2)]
# A notice at each corridor's end, low enough to fill the view when the walk stops 1 m from
# that wall and turns: without them the view there is a plain wall above a periodic floor,
# where the tracker slid along the tiles at every corner (ATE 2 m).
POSTERS += [("east", 8.7, 39, 0.8), ("north", 10.7, 40, 0.8), ("west", 8.7, 41, 0.8),
            ("south", 10.7, 42, 0.8)]


# The outer walls seen from inside: origin, u axis (along the wall, left to right as seen),
# length, and the offset 5 mm towards the corridor for a poster on it.
WALLS = {
    "south": ((OUTER_X, 0, 0), [-1, 0, 0], OUTER_X, (0, 0.005)),
    "east": ((OUTER_X, OUTER_Y, 0), [0, -1, 0], OUTER_Y, (-0.005, 0)),
    "north": ((0, OUTER_Y, 0), [1, 0, 0], OUTER_X, (0, -0.005)),
    "west": ((0, 0, 0), [0, 1, 0], OUTER_Y, (0.005, 0)),
}
WALL_TEXTURE = {"south": "brick", "east": "plaster", "north": "plaster_warm", "west": "plaster"}


def scene_planes():
    out = [plane("floor", "floor_tiles", (0, 0, 0), [1, 0, 0], [0, 1, 0], rect(OUTER_X, OUTER_Y)),
           plane("ceiling", "ceiling", (0, 0, H), [0, 1, 0], [1, 0, 0], rect(OUTER_Y, OUTER_X))]
    for name, (origin, u, length, _) in WALLS.items():
        out.append(plane(f"wall_{name}", WALL_TEXTURE[name], origin, u, [0, 0, 1], rect(length, H)))
    for k, (wall, along, _, low) in enumerate(POSTERS):
        origin, u, _, (dx, dy) = WALLS[wall]
        o = (origin[0] + along * u[0] + dx, origin[1] + along * u[1] + dy, low)
        out.append(plane(f"poster_{k}_{wall}", f"poster_{k}", o, u, [0, 0, 1], rect(0.6, 0.85)))
    return out


def key_poses():
    """(x, y, yaw): the ring's centre line, anticlockwise from the south side, once round and
    on to the far end of the first side."""
    a, bx, by = WIDTH / 2, OUTER_X - WIDTH / 2, OUTER_Y - WIDTH / 2
    # Each corner with the heading after it: walk to the corner, then turn a quarter left.
    corners = [(bx, a, math.pi / 2), (bx, by, math.pi), (a, by, 1.5 * math.pi), (a, a, 2 * math.pi)]
    poses = [(a + 2.0, a, 0.0)]
    for x, y, yaw in corners:
        poses += [(x, y, yaw - math.pi / 2), (x, y, yaw)]
    poses.append((bx - 2.0, a, 2 * math.pi))  # past the start, along the first side again
    return poses


def main():
    print("# A corridor ring around a closed block (x east, y north, z up; floor at z = 0), walked")
    print("# once round and on past the start: the loop-closure scene.")
    print("# Written by scripts/make_loop_scene.py; keys are documented in docs/SCENES.md.")
    print("# Rendered (outside git, about 7 minutes here): tessera synth "
          "config/scenes/loop.yaml loop.oni")
    print("name: loop\nseed: 2028")
    print(f"frames: {FRAMES}\nfps: 30\nsensor: kinect_v1\n")
    print("textures:")
    print("  - {id: brick, generator: brick, seed: 11, brick_width_m: 0.215, brick_height_m: 0.065,"
          " mortar_m: 0.01, bricks_per_period: 3}")
    print("  - {id: floor_tiles, generator: tiles, seed: 12, tile_m: 0.3, grout_m: 0.006,"
          " tiles_per_period: 2}")
    print("  - {id: plaster, generator: plaster, seed: 13}")
    print("  - {id: plaster_warm, generator: plaster, seed: 22, colour: [236, 222, 200]}")
    print("  - {id: ceiling, generator: plaster, seed: 14, colour: [240, 240, 236]}")
    print("  - {id: block, generator: plaster, seed: 24, colour: [214, 226, 236]}")
    for k, (_, _, seed, _) in enumerate(POSTERS):
        print(f"  - {{id: poster_{k}, generator: poster, seed: {seed}, width_m: 0.6, "
              "height_m: 0.85}")
    print("\nplanes:")
    print("\n".join(scene_planes()))
    print("\nboxes:")
    print(f"  - {{id: block, min: [{WIDTH:.1f}, {WIDTH:.1f}, 0.0], "
          f"max: [{OUTER_X - WIDTH:.1f}, {OUTER_Y - WIDTH:.1f}, {H:.1f}], top_texture: block, "
          "side_texture: block}")
    print("\ncamera:\n  waypoints:")
    for x, y, yaw in waypoints(key_poses()):
        lx, ly = x + LOOK_AHEAD * math.cos(yaw), y + LOOK_AHEAD * math.sin(yaw)
        print(f"    - {{position: [{x:.3f}, {y:.3f}, {EYE}], "
              f"look_at: [{lx:.3f}, {ly:.3f}, {LOOK_Z}]}}")


if __name__ == "__main__":
    main()
