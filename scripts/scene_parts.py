"""What the scene scripts share: plane entries in the scene YAML, and camera paths (key poses
(x, y, yaw) subdivided into waypoints)."""
import math


def waypoints(poses, max_step_m=0.25, max_turn=math.radians(12)):
    """Key poses subdivided so that every segment moves about as much (the renderer spends the
    same number of frames on each); each turn takes the short way round."""
    out = [poses[0]]
    for (x0, y0, a0), (x1, y1, a1) in zip(poses, poses[1:]):
        turn = math.atan2(math.sin(a1 - a0), math.cos(a1 - a0))
        n = max(1, math.ceil(max(math.hypot(x1 - x0, y1 - y0) / max_step_m,
                                 abs(turn) / max_turn)))
        for i in range(1, n + 1):
            t = i / n
            out.append((x0 + t * (x1 - x0), y0 + t * (y1 - y0), a0 + t * turn))
    return out


def plane(pid, texture, origin, u, v, polygon, extra=""):
    """One `planes` entry of a scene file (docs/SCENES.md)."""
    pts = ", ".join(f"[{a:.3f}, {b:.3f}]" for a, b in polygon)
    o = ", ".join(f"{x:.3f}" for x in origin)
    return (f"  - {{id: {pid}, texture: {texture}, origin: [{o}], u_axis: {u}, v_axis: {v},\n"
            f"     polygon: [{pts}]{extra}}}")


def rect(w, h):
    return [(0, 0), (w, 0), (w, h), (0, h)]
