#!/usr/bin/env python3
"""Writes config/scenes/corridor.yaml: four rooms along a 24 m corridor, walked through room by
room (3,200 frames, about 110 m of camera path). It is the long-run scene for memory and
throughput benches; the YAML is committed, this script documents how it was made.

Usage: scripts/make_corridor_scene.py > config/scenes/corridor.yaml
"""
import math

from scene_parts import plane, rect, waypoints

FRAMES = 3200
ROOM_W, ROOM_D, H = 6.0, 5.0, 2.6      # each room: 6 m along the corridor, 5 m deep
CORRIDOR_W, WALL = 2.0, 0.15           # corridor width, wall thickness
ROOMS = 4
LENGTH = ROOMS * ROOM_W
DOOR_W, DOOR_H = 1.2, 2.1

# Rooms 0 and 2 are furnished alike (the same textures seen again far away: reuse across the
# run); rooms 1 and 3 each have their own.
ROOM_STYLE = [
    dict(floor="floor_tiles", walls="plaster", side="brick", poster="poster_a"),
    dict(floor="parquet", walls="plaster_warm", side="plaster_warm", poster="poster_b"),
    dict(floor="floor_tiles", walls="plaster", side="brick", poster="poster_a"),
    dict(floor="cobbles", walls="brick", side="plaster", poster="poster_c"),
]


def scene_planes():
    out = []
    out.append(plane("corridor_floor", "floor_tiles", (0, 0, 0), [1, 0, 0], [0, 1, 0],
                     rect(LENGTH, CORRIDOR_W)))
    out.append(plane("corridor_ceiling", "ceiling", (0, 0, H), [0, 1, 0], [1, 0, 0],
                     rect(CORRIDOR_W, LENGTH)))
    out.append(plane("corridor_south", "plaster", (LENGTH, 0, 0), [-1, 0, 0], [0, 0, 1],
                     rect(LENGTH, H)))
    out.append(plane("corridor_west", "plaster", (0, CORRIDOR_W, 0), [0, -1, 0], [0, 0, 1],
                     rect(CORRIDOR_W, H)))
    out.append(plane("corridor_east", "plaster", (LENGTH, 0, 0), [0, 1, 0], [0, 0, 1],
                     rect(CORRIDOR_W, H)))
    # The corridor's north wall, seen from the corridor, with one door per room.
    wall = [(0, 0)]
    for k in range(ROOMS):
        a = k * ROOM_W + (ROOM_W - DOOR_W) / 2
        wall += [(a, 0), (a, DOOR_H), (a + DOOR_W, DOOR_H), (a + DOOR_W, 0)]
    wall += [(LENGTH, 0), (LENGTH, H), (0, H)]
    out.append(plane("corridor_north", "plaster", (0, CORRIDOR_W, 0), [1, 0, 0], [0, 0, 1], wall))
    y0 = CORRIDOR_W + WALL
    for k, style in enumerate(ROOM_STYLE):
        x0, x1 = k * ROOM_W + WALL / 2, (k + 1) * ROOM_W - WALL / 2
        w, y1 = x1 - x0, y0 + ROOM_D
        out.append(plane(f"room{k}_floor", style["floor"], (x0, y0, 0), [1, 0, 0], [0, 1, 0],
                         rect(w, ROOM_D)))
        out.append(plane(f"room{k}_ceiling", "ceiling", (x0, y0, H), [0, 1, 0], [1, 0, 0],
                         rect(ROOM_D, w)))
        out.append(plane(f"room{k}_north", style["walls"], (x0, y1, 0), [1, 0, 0], [0, 0, 1],
                         rect(w, H)))
        out.append(plane(f"room{k}_west", style["side"], (x0, y0, 0), [0, 1, 0], [0, 0, 1],
                         rect(ROOM_D, H)))
        out.append(plane(f"room{k}_east", style["side"], (x1, y1, 0), [0, -1, 0], [0, 0, 1],
                         rect(ROOM_D, H)))
        # The room's side of the door wall.
        a = (ROOM_W - DOOR_W) / 2 - WALL / 2
        door = [(0, 0), (a, 0), (a, DOOR_H), (a + DOOR_W, DOOR_H), (a + DOOR_W, 0), (w, 0), (w, H),
                (0, H)]
        out.append(plane(f"room{k}_south", style["walls"], (x1, y0, 0), [-1, 0, 0], [0, 0, 1],
                         [(w - u, v) for u, v in door][::-1]))
        out.append(plane(f"room{k}_poster", style["poster"], (x0 + 2.0, y1 - 0.005, 1.2),
                         [1, 0, 0], [0, 0, 1], rect(0.6, 0.85)))
    return out


def scene_boxes():
    out = []
    y0 = CORRIDOR_W + WALL
    for k, style in enumerate(ROOM_STYLE):
        x0 = k * ROOM_W
        out.append(f"  - {{id: room{k}_table, min: [{x0 + 1.2:.2f}, {y0 + 2.6:.2f}, 0.72], "
                   f"max: [{x0 + 2.8:.2f}, {y0 + 3.4:.2f}, 0.76], top_texture: oak}}")
        out.append(f"  - {{id: room{k}_cabinet, min: [{x0 + 4.6:.2f}, {y0 + 3.9:.2f}, 0.0], "
                   f"max: [{x0 + 5.4:.2f}, {y0 + 4.6:.2f}, 0.8], top_texture: oak, "
                   f"side_texture: oak}}")
    return out


def key_poses():
    """(x, y, yaw) key poses: along the corridor, into each room, around it, and out."""
    poses = [(0.8, 1.0, 0.0)]
    for k in range(ROOMS):
        cx = k * ROOM_W + ROOM_W / 2
        cy = CORRIDOR_W + WALL + ROOM_D / 2
        poses += [(cx, 1.0, 0.0), (cx, 1.0, math.pi / 2), (cx, cy - 0.6, math.pi / 2)]
        # A look around the room, one full turn, then back to the door.
        for i in range(1, 9):
            yaw = math.pi / 2 + i * math.pi / 4
            poses.append((cx + 0.6 * math.cos(yaw - math.pi / 2),
                          cy + 0.6 * math.sin(yaw - math.pi / 2), yaw))
        poses += [(cx, cy - 0.6, -math.pi / 2), (cx, 1.0, -math.pi / 2), (cx, 1.0, 0.0)]
    poses.append((LENGTH - 0.8, 1.0, 0.0))
    return poses


def main():
    print("# Four rooms along a 24 m corridor (x east, y north, z up; floor at z = 0), walked")
    print("# through room by room: the long-run scene for memory and throughput benches.")
    print("# Written by scripts/make_corridor_scene.py; keys are documented in docs/SCENES.md.")
    print("# Rendered (outside git, about 14 minutes here): tessera synth "
          "config/scenes/corridor.yaml corridor.oni")
    print("name: corridor\nseed: 2027")
    print(f"frames: {FRAMES}\nfps: 30\nsensor: kinect_v1\n")
    print("textures:")
    print("  - {id: brick, generator: brick, seed: 11, brick_width_m: 0.215, brick_height_m: 0.065,"
          " mortar_m: 0.01, bricks_per_period: 3}")
    print("  - {id: floor_tiles, generator: tiles, seed: 12, tile_m: 0.3, grout_m: 0.006,"
          " tiles_per_period: 2}")
    print("  - {id: parquet, generator: wood, seed: 21}")
    print("  - {id: oak, generator: wood, seed: 18}")
    print("  - {id: plaster, generator: plaster, seed: 13}")
    print("  - {id: plaster_warm, generator: plaster, seed: 22, colour: [236, 222, 200]}")
    print("  - {id: ceiling, generator: plaster, seed: 14, colour: [240, 240, 236]}")
    print("  - {id: cobbles, generator: cobblestone, seed: 19, period_m: 0.4, stones_per_period: 7}")
    print("  - {id: poster_a, generator: poster, seed: 15, width_m: 0.6, height_m: 0.85}")
    print("  - {id: poster_b, generator: poster, seed: 16, width_m: 0.6, height_m: 0.85}")
    print("  - {id: poster_c, generator: poster, seed: 23, width_m: 0.6, height_m: 0.85}")
    print("\nplanes:")
    print("\n".join(scene_planes()))
    print("\nboxes:")
    print("\n".join(scene_boxes()))
    print("\ncamera:\n  waypoints:")
    for x, y, yaw in waypoints(key_poses()):
        lx, ly = x + 2.5 * math.cos(yaw), y + 2.5 * math.sin(yaw)
        print(f"    - {{position: [{x:.3f}, {y:.3f}, 1.5], look_at: [{lx:.3f}, {ly:.3f}, 0.9]}}")


if __name__ == "__main__":
    main()
