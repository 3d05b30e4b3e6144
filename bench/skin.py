"""Does the skinned body hold together? Edge stretch and body-to-skeleton distance of the GLB's mesh.

For every shared rig (the clips of ``../shared/data/bvh`` and ``../shared/data/bvh/wide``), every
setting and both bodies, the mesh is posed exactly as a viewer of our GLB poses it, and measured
at EVERY frame of the clip (issue 23, point 5). Run by hand: ``python bench/skin.py`` (a few
minutes; ``--jobs 2`` on two cores); ``--json PATH`` saves every figure for a before/after comparison.

Settings (rows)
    ``captured``: the clip as read, on its own skeleton (no pipeline): the reference.
    ``identity-rubber``: extrapolation, correction, springs, contacts and stretch all off
    (extrapolation switched off outright, which is omega 1 exactly), sub-joints ON (4 a link,
    the default): the captured motion on the rubber skeleton. ``identity-straight``: the same with
    sub-joints OFF (straight links). ``subtle``, ``cartoon``, ``looney``: the presets.
    ``looney+auto-stretch``: looney with ``auto_stretch.enabled`` (the only row whose GLB carries
    thickness scales).

Bodies
    ``default``: `mocap_exaggerate.rig.body.default_skin` grown from the clip's skeleton (with the run's
    rigid joints, as the GLB does). ``makehuman``: the MakeHuman CC0 body
    (``../shared/data/skin/makehuman_base.obj``) bound to the clip's skeleton by
    `mocap_exaggerate.rig.binding.bind_skin`, as ``convert``/``--skin`` binds it.

How the mesh is posed (what the GLB holds)
    The bound skin is re-weighted onto the output skeleton by `mocap_exaggerate.jobs.outputs.output_skin`
    (4 influences, the GLB's default; `reweight` on the rubber skeleton). Each output joint's world
    transform is the forward kinematics of the output motion's local rotations and translations
    (the GLB's animation tracks), with the uniform world scale ``thickness`` of
    `mocap_exaggerate.jobs.outputs.output_thickness` where the GLB writes one; the inverse bind matrices
    undo the output skeleton's rest positions (identity orientations). So a vertex is
    ``sum_k w_k (s_j R_j (v - rest_j) + p_j)`` over its joints j (the GLB's turn onto +Y and its
    unit scale are one similarity for the whole scene and change no figure below). The captured
    row poses the bound skin (all its influences) on the clip's own skeleton the same way.
    Linear blend skinning is one sparse matrix (3V x 12J) times the joints' 3x4 matrices, in blocks
    of frames.

Figures (h = the clip skeleton's height)
    ``>1.5x``, ``>2x``: share of the mesh's edges (unique undirected edges of its triangles; edges
    of no bind length left out) whose length passes 1.5 (2) times their bind length at some frame.
    ``worst``: the largest edge ratio met, and ``@`` its frame.
    ``dist``: the largest, over frames and over points along the output skeleton's links, of the
    distance from the point to the nearest point of the posed body, in h. The skeleton's points:
    every joint of the output skeleton that carries the body (sub-joints, and the original joints
    the run does not prune as riding rigidly: fingers, toes, face, twist, share and helper bones are
    left out, as the default body gives them no piece of their own; the same points for both
    bodies) and the points at 1/4, 1/2 and 3/4 of every link (sub-link) ending at one, at the output
    FK's world positions. The body's points: its vertices, and points every `SPACING` h along each
    of its edges, posed as the renderer draws an edge (straight between its posed ends). Vertices
    alone would not do: the default body's capsules have vertices only in their round ends, so the
    middle of a long link is 0.15-0.2 h from the nearest vertex of its own capsule, 0.05 h from its
    surface. ``rest``: the same figure with the skeleton in its rest (bind) pose and the mesh as
    bound, each point measured against the piece(s) of the mesh that carry it (a piece: a connected
    part; it carries a point when a vertex of it is weighted to the point's joint or an end of its
    link; `own_piece_distance`): on rigs whose rest pose packs the pieces together (iClone's legs and
    arms point up beside the spine) every point is near SOME piece at rest (0.027 h, ``rest_any`` in
    the JSON), which no posed frame can match, so measured against anything the captured motion itself
    read 1.87. ``ratio`` = dist / rest. ``/cap``: dist over the captured row's dist (same rig and body).
    ``grow``: the largest, over points and frames, of a point's distance minus its own rest distance
    (to anything), in h. ``/cap`` compares with the capture instead. The distance figures are taken at every frame (nearest body
    point by a `scipy.spatial.cKDTree` per frame) unless ``--distance-step K`` asks for every K-th
    frame, in which case the frames of the largest edge ratio and of the most edges past 2x are added.

Targets (PASS/FAIL per rig; a difference is the row's 2x share minus the reference's, in
percentage points, and only an excess fails: fewer stretched edges than the reference pass)
    T1 makehuman identity-rubber within 0.1 points of identity-straight;
    T2 makehuman cartoon within 0.5 points of captured;
    T3 makehuman looney within 1.5 points of captured;
    T4 default body: ``ratio`` at most 1.5 on every row measured.

Deterministic: the same code and data give the same table and JSON (bar the ``timings`` key).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import FPS, SHARED  # noqa: E402  same folder: run as python bench/skin.py

SETTINGS = ("captured", "identity-rubber", "identity-straight", "subtle", "cartoon", "looney", "looney+auto-stretch")
BODIES = ("default", "makehuman")
SKIN_FILE = SHARED.parent / "skin" / "makehuman_base.obj"
#: Where along each link the distance figure puts points, besides the joints themselves.
ALONG = (0.25, 0.5, 0.75)
#: The body's points for the distance figures: its vertices and points this far apart (in skeleton heights)
#: along each of its edges.
SPACING = 0.02
#: Largest arrays of one block of frames, in float64 elements.
BLOCK_ELEMENTS = 3_000_000
TARGETS = (
    ("T1", "makehuman identity-rubber 2x share <= identity-straight + 0.1 pt"),
    ("T2", "makehuman cartoon 2x share <= captured + 0.5 pt"),
    ("T3", "makehuman looney 2x share <= captured + 1.5 pt"),
    ("T4", "default body dist <= 1.5 x its rest figure, every row"),
)


# ---------------------------------------------------------------------------- settings


def setting_config(name: str):
    """The PipelineConfig of a setting (None for ``captured``)."""
    from mocap_exaggerate.config import PipelineConfig, load_preset
    from mocap_exaggerate.stages.contacts import ContactConfig
    from mocap_exaggerate.stages.correct import CorrectConfig
    from mocap_exaggerate.stages.extrapolate import ExtrapolateConfig
    from mocap_exaggerate.stages.springs import SpringConfig
    from mocap_exaggerate.stages.stretch import AutoStretchConfig
    from mocap_exaggerate.stages.subjoints import SubjointConfig

    if name == "captured":
        return None
    if name.startswith("identity-"):
        return PipelineConfig(
            extrapolate=ExtrapolateConfig(enabled=False, omega=1.0), correct=CorrectConfig(enabled=False),
            springs=SpringConfig(enabled=False), contacts=ContactConfig(enabled=False),
            auto_stretch=AutoStretchConfig(enabled=False),
            subjoints=SubjointConfig(enabled=name == "identity-rubber"))
    if name == "looney+auto-stretch":
        looney = load_preset("looney")
        return replace(looney, auto_stretch=replace(looney.auto_stretch, enabled=True))
    return load_preset(name)


# ---------------------------------------------------------------------------- posing and measuring


def lbs_operator(skin, joint_index: np.ndarray, num_joints: int):
    """Sparse (3V, 12J): posed vertices (v*3 + axis) from the joints' 3x4 matrices (j*12 + row*4 + col)."""
    from scipy.sparse import csr_matrix

    vertex, slot = np.nonzero(skin.weights > 0)
    joint = joint_index[skin.joints[vertex, slot]]
    weight = skin.weights[vertex, slot]
    homogeneous = np.concatenate([skin.vertices, np.ones((skin.num_vertices, 1))], axis=1)
    axis = np.arange(3)[None, :, None]
    column = np.arange(4)[None, None, :]
    rows = np.broadcast_to(vertex[:, None, None] * 3 + axis, (len(vertex), 3, 4))
    cols = joint[:, None, None] * 12 + axis * 4 + column
    vals = np.broadcast_to(weight[:, None, None] * homogeneous[vertex][:, None, :], (len(vertex), 3, 4))
    return csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * skin.num_vertices, 12 * num_joints))


def unique_edges(faces: np.ndarray) -> np.ndarray:
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(edges, axis=1), axis=0)


def link_points(positions: np.ndarray, parents: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """(..., P, 3): the joints ``keep`` (J,) picks, and the points at `ALONG` of the links ending at them."""
    child = np.flatnonzero((parents >= 0) & keep)
    head, tail = positions[..., parents[child], :], positions[..., child, :]
    return np.concatenate([positions[..., np.flatnonzero(keep), :]] + [(1.0 - t) * head + t * tail for t in ALONG],
                          axis=-2)


def nearest(vertices: np.ndarray, points: np.ndarray) -> np.ndarray:
    from scipy.spatial import cKDTree

    return cKDTree(vertices, balanced_tree=False, compact_nodes=False).query(points)[0]


def own_piece_distance(skin, index: np.ndarray, edge_ends: np.ndarray, body_rest: np.ndarray,
                       rest_points: np.ndarray, parents: np.ndarray, carried: np.ndarray) -> np.ndarray:
    """Each skeleton point's rest distance to the piece(s) of the body that carry it.

    A piece is a connected part of the mesh; it carries a point when one of its vertices is
    weighted to the point's joint or to an end of the point's link. On a rig whose rest pose
    packs the limbs together (iClone's legs and arms point up beside the spine) every point
    is near SOME piece at rest, so the nearest-anything figure is small there and no posed
    frame can match it; measured against its own piece, the rest figure is the body's own
    thickness around its skeleton. ``edge_ends`` (E', 2): the edge of each point along an edge.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges = unique_edges(skin.faces)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(skin.num_vertices,) * 2)
    _, piece = connected_components(graph, directed=False)
    piece_of_point = np.concatenate([piece, piece[edge_ends[:, 0]]])
    child = np.flatnonzero((parents >= 0) & carried)
    ends = np.concatenate([np.column_stack([np.flatnonzero(carried), np.maximum(parents[np.flatnonzero(carried)], 0)])]
                          + [np.column_stack([parents[child], child])] * len(ALONG))
    touching = np.zeros((piece.max() + 1, len(parents)), bool)
    rows = np.repeat(piece, skin.joints.shape[1])
    used = skin.weights.ravel() > 0
    touching[rows[used], index[skin.joints.ravel()[used]]] = True
    own = np.full(len(rest_points), np.inf)
    for p in range(piece.max() + 1):
        mine = touching[p, ends[:, 0]] | touching[p, ends[:, 1]]
        if mine.any():
            own[mine] = np.minimum(own[mine], nearest(body_rest[piece_of_point == p], rest_points[mine]))
    anywhere = nearest(body_rest, rest_points)
    return np.where(np.isfinite(own), own, anywhere)


def measure_body(skin, skeleton, rotations: np.ndarray, positions: np.ndarray, thickness, height: float,
                 step: int, carried: np.ndarray) -> dict:
    """Every figure of one posed body: ``skin`` bound to ``skeleton`` (its rest = the bind pose),
    posed by world ``rotations`` (F, J, 4), ``positions`` (F, J, 3) and ``thickness`` (F, J) or None;
    ``carried`` (J,): the joints (and links ending at them) the distance figures measure from."""
    from scipy.sparse import csr_matrix, identity, kron, vstack

    from mocap_exaggerate.core.rotations import quat_to_matrix

    frames, joints = positions.shape[:2]
    rest = skeleton.rest_positions()
    index = np.array([skeleton.index(n) for n in skin.joint_names], dtype=np.int64)
    edges = unique_edges(skin.faces)
    bind_sq = np.sum((skin.vertices[edges[:, 1]] - skin.vertices[edges[:, 0]]) ** 2, axis=1)
    edges, bind_sq = edges[bind_sq > (1e-9 * height) ** 2], bind_sq[bind_sq > (1e-9 * height) ** 2]
    # Points along the edges (for the distance figures), posed as their edge: between its posed ends.
    pieces = np.maximum(np.ceil(np.sqrt(bind_sq) / (SPACING * height)).astype(np.int64), 1)
    edge = np.repeat(np.arange(len(edges)), pieces - 1)
    at = (np.arange(len(edge)) - np.repeat(np.cumsum(pieces - 1) - (pieces - 1), pieces - 1) + 1) / pieces[edge]
    between = csr_matrix((np.concatenate([1.0 - at, at]), (np.tile(np.arange(len(edge)), 2),
                                                          np.concatenate([edges[edge, 0], edges[edge, 1]]))),
                         shape=(len(edge), skin.num_vertices))
    vertices_only = lbs_operator(skin, index, joints)
    operator = vstack([vertices_only, kron(between, identity(3, format="csr"), format="csr") @ vertices_only],
                      format="csr")
    count = skin.num_vertices
    parents = np.asarray(skeleton.parents)
    body_rest = np.concatenate([skin.vertices, between @ skin.vertices])
    rest_points = link_points(rest, parents, carried)
    rest_distance = nearest(body_rest, rest_points)
    own_distance = own_piece_distance(skin, index, edges[edge], body_rest, rest_points, parents, carried)

    per_edge = np.zeros(len(edges))  # largest squared ratio met
    frame_worst = np.zeros(frames)  # per frame, the largest squared ratio
    frame_over2 = np.zeros(frames, dtype=np.int64)  # per frame, edges past 2x
    distances = np.full(frames, np.nan)
    grows = np.full(frames, np.nan)
    block = int(np.clip(BLOCK_ELEMENTS // (3 * max(len(edges), count + len(edge), 1)), 1, 256))
    sampled = np.zeros(frames, bool)
    sampled[::step] = True
    for start in range(0, frames, block):
        stop = min(start + block, frames)
        turn = quat_to_matrix(rotations[start:stop])  # (B, J, 3, 3)
        if thickness is not None:
            turn = turn * thickness[start:stop, :, None, None]
        matrices = np.empty((stop - start, joints, 3, 4))
        matrices[..., :3] = turn
        matrices[..., 3] = positions[start:stop] - np.einsum("bjac,jc->bja", turn, rest)
        posed = (operator @ matrices.reshape(stop - start, -1).T).T.reshape(stop - start, -1, 3)
        squared = np.sum((posed[:, edges[:, 1]] - posed[:, edges[:, 0]]) ** 2, axis=2) / bind_sq
        np.maximum(per_edge, squared.max(axis=0), out=per_edge)
        frame_worst[start:stop] = squared.max(axis=1)
        frame_over2[start:stop] = np.count_nonzero(squared > 4.0, axis=1)
        if step == 1:
            points = link_points(positions[start:stop], parents, carried)
            for i in range(stop - start):  # one tree per frame
                d = nearest(posed[i], points[i])
                distances[start + i] = d.max()
                grows[start + i] = (d - rest_distance).max()
        else:
            for i in np.flatnonzero(sampled[start:stop]):
                d = nearest(posed[i], link_points(positions[start + i], parents, carried))
                distances[start + i], grows[start + i] = d.max(), (d - rest_distance).max()
    if step > 1:  # the frames of the worst stretch too
        extra = sorted({int(np.argmax(frame_worst)), int(np.argmax(frame_over2))} - set(np.flatnonzero(sampled)))
        for f in extra:
            posed = (operator @ _matrices(rotations[f], positions[f], None if thickness is None else thickness[f],
                                          rest).ravel()).reshape(-1, 3)
            d = nearest(posed, link_points(positions[f], parents, carried))
            distances[f], grows[f] = d.max(), (d - rest_distance).max()
    worst_frame = int(np.argmax(frame_worst))
    far_frame = int(np.nanargmax(distances))
    rest_figure = float(own_distance.max())
    return {
        "vertices": int(skin.num_vertices), "edges": int(len(edges)), "edge_points": int(len(edge)),
        "over_1_5": float(np.mean(per_edge > 2.25)), "over_2": float(np.mean(per_edge > 4.0)),
        "worst_ratio": float(np.sqrt(frame_worst.max())), "worst_frame": worst_frame,
        "most_over_2_frame": int(np.argmax(frame_over2)), "most_over_2": int(frame_over2.max()),
        "dist": float(distances[far_frame] / height), "dist_frame": far_frame,
        "rest": rest_figure / height, "rest_any": float(rest_distance.max() / height),
        "ratio": float(distances[far_frame] / rest_figure) if rest_figure > 0 else float("inf"),
        "grow": float(np.nanmax(grows) / height), "grow_frame": int(np.nanargmax(grows)),
        "distance_frames": int(np.count_nonzero(np.isfinite(distances))),
    }


def _matrices(rotation, position, thickness, rest) -> np.ndarray:
    from mocap_exaggerate.core.rotations import quat_to_matrix

    turn = quat_to_matrix(rotation)
    if thickness is not None:
        turn = turn * thickness[:, None, None]
    out = np.empty((len(position), 3, 4))
    out[..., :3] = turn
    out[..., 3] = position - np.einsum("jac,jc->ja", turn, rest)
    return out


# ---------------------------------------------------------------------------- one rig


_MAKEHUMAN = None


def makehuman():
    global _MAKEHUMAN
    if _MAKEHUMAN is None:
        from mocap_exaggerate.io.skin import load_skin

        _MAKEHUMAN = load_skin(SKIN_FILE)
    return _MAKEHUMAN


def measure_rig(task: tuple) -> list[dict]:
    """Rows (one per setting x body) of one clip."""
    path, rig, settings, bodies, cut, step = task
    from mocap_exaggerate.analysis.branches import minor_branches
    from mocap_exaggerate.io.bvh import read_bvh
    from mocap_exaggerate.jobs.outputs import at_bind_pose, base_skin, output_skin, output_thickness
    from mocap_exaggerate.pipeline import run
    from mocap_exaggerate.rig.binding import bind_skin
    from mocap_exaggerate.rig.body import default_skin

    motion, _ = read_bvh(Path(path), fps=FPS.get(Path(path).name))
    if cut:
        motion = motion.slice(slice(0, cut))
    skeleton = motion.skeleton
    height = skeleton.height()
    bound = {}
    if "makehuman" in bodies:
        bound["makehuman"] = bind_skin(makehuman(), skeleton)[0]
    rows = []
    for setting in settings:
        started = time.perf_counter()
        base = {"rig": rig, "setting": setting, "frames": motion.num_frames, "height": height}
        try:
            if setting == "captured":
                rotations, positions = motion.forward_kinematics()
                out_skeleton, thickness, result = skeleton, None, None
                carried = ~minor_branches(skeleton)
            else:
                result = run(motion, setting_config(setting))
                out_skeleton = result.motion.skeleton
                rotations, positions = result.motion.forward_kinematics()  # what the GLB's tracks give
                thickness = output_thickness(result)
                # Sub-joints lie on rubber links only; the original joints as the run pruned them.
                carried = np.ones(out_skeleton.num_joints, bool)
                carried[result.original_index] = ~(result.hierarchy.rigid if result.hierarchy is not None
                                                   else minor_branches(skeleton))
            ran = time.perf_counter() - started
        except Exception as error:  # noqa: BLE001  a bench row, not a crash of the whole table
            rows += [{**base, "body": b, "error": f"{type(error).__name__}: {error}"} for b in bodies]
            continue
        for body in bodies:
            tick = time.perf_counter()
            try:
                # A character bound in its own pose (`Skin.pose`) is posed from there, as the GLB's rest.
                shown, turns = out_skeleton, rotations
                if setting == "captured":
                    skin = bound[body] if body == "makehuman" else default_skin(skeleton)
                    if skin.pose:
                        posed, _, skin = at_bind_pose(motion, None, skin)
                        shown, turns = posed.skeleton, posed.world_rotations()
                else:
                    clip, posed, based = at_bind_pose(motion, result, base_skin(motion, result, bound.get(body)))
                    skin = output_skin(clip, posed, based)
                    if posed is not result:
                        shown, turns = posed.motion.skeleton, posed.world_rotations
                figures = measure_body(skin, shown, turns, positions, thickness, height, step, carried)
            except Exception as error:  # noqa: BLE001
                rows.append({**base, "body": body, "error": f"{type(error).__name__}: {error}"})
                continue
            rows.append({**base, "body": body, "joints": int(out_skeleton.num_joints),
                         "thickness": thickness is not None, **figures,
                         "seconds": {"run": ran, "measure": time.perf_counter() - tick}})
    captured = {r["body"]: r["dist"] for r in rows if r["setting"] == "captured" and "error" not in r}
    for r in rows:
        if "error" not in r:
            r["vs_captured"] = r["dist"] / captured[r["body"]] if r["body"] in captured else None
    return rows


# ---------------------------------------------------------------------------- printing


HEADER = (f"{'rig':44s} {'setting':19s} {'body':9s} {'frames':>6s} {'>1.5x%':>7s} {'>2x%':>6s} {'worst':>6s} "
          f"{'@':>5s} {'dist':>6s} {'rest':>6s} {'ratio':>5s} {'@':>5s} {'grow':>6s} {'/cap':>5s}")


def row_line(r: dict) -> str:
    head = f"{r['rig'][:44]:44s} {r['setting']:19s} {r['body']:9s} {r['frames']:6d}"
    if "error" in r:
        return f"{head} ERROR {r['error'][:200]}"
    return (f"{head} {100 * r['over_1_5']:7.3f} {100 * r['over_2']:6.3f} {r['worst_ratio']:6.2f} {r['worst_frame']:5d} "
            f"{r['dist']:6.3f} {r['rest']:6.3f} {r['ratio']:5.2f} {r['dist_frame']:5d} {r['grow']:6.3f} "
            f"{'-' if r['vs_captured'] is None else format(r['vs_captured'], '.2f'):>5s}"
            + (" thick" if r["thickness"] else ""))


def targets(rows: list[dict]) -> dict[str, dict]:
    """Per rig: each target's figure (points, or the worst ratio) and PASS/FAIL (None: not measured)."""
    by = {(r["rig"], r["setting"], r["body"]): r for r in rows if "error" not in r}
    out = {}
    for rig in dict.fromkeys(r["rig"] for r in rows):
        def share(setting, rig=rig):
            r = by.get((rig, setting, "makehuman"))
            return None if r is None else 100 * r["over_2"]

        checks = {}
        for name, setting, reference, slack in (("T1", "identity-rubber", "identity-straight", 0.1),
                                                ("T2", "cartoon", "captured", 0.5),
                                                ("T3", "looney", "captured", 1.5)):
            a, b = share(setting), share(reference)
            diff = None if a is None or b is None else a - b
            checks[name] = {"value": diff, "pass": None if diff is None else bool(diff <= slack)}
        ratios = [r["ratio"] for (g, s, b), r in by.items() if g == rig and b == "default"]
        worst = max(ratios) if ratios else None
        checks["T4"] = {"value": worst, "pass": None if worst is None else bool(worst <= 1.5)}
        versus = [r["vs_captured"] for (g, s, b), r in by.items() if g == rig and b == "default"
                  and r["vs_captured"] is not None]
        checks["T4_vs_captured"] = max(versus) if versus else None  # not a target: for reading T4
        errors = [r for r in rows if r["rig"] == rig and "error" in r]
        if errors:
            checks["errors"] = len(errors)
        out[rig] = checks
    return out


def summary(rows: list[dict]) -> list[dict]:
    lines = []
    for setting in dict.fromkeys(r["setting"] for r in rows):
        for body in dict.fromkeys(r["body"] for r in rows):
            got = [r for r in rows if r["setting"] == setting and r["body"] == body and "error" not in r]
            if not got:
                continue
            line = {"setting": setting, "body": body, "rigs": len(got)}
            for key in ("over_1_5", "over_2", "ratio", "grow", "vs_captured"):
                if any(r[key] is None for r in got):
                    continue
                values = np.array([r[key] for r in got])
                worst = got[int(np.argmax(values))]["rig"]
                line[key] = {"worst": float(values.max()), "median": float(np.median(values)), "worst_rig": worst}
            lines.append(line)
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", default="*", help="glob over clip names (wide clips also as wide/NAME)")
    parser.add_argument("--settings", default=",".join(SETTINGS), help=f"comma-separated, of {', '.join(SETTINGS)}")
    parser.add_argument("--bodies", default=",".join(BODIES), help="default, makehuman or both")
    parser.add_argument("--frames", type=int, default=0, help="only each clip's first N frames (a quick look)")
    parser.add_argument("--distance-step", type=int, default=1,
                        help="distance figures every K-th frame (plus the worst stretch frames); default every frame")
    parser.add_argument("--jobs", type=int, default=1, help="rigs measured at once (processes)")
    parser.add_argument("--data", type=Path, default=SHARED)
    parser.add_argument("--json", type=Path, default=None, help="also write every figure here")
    args = parser.parse_args()
    settings = [s for s in args.settings.split(",") if s]
    bodies = [b for b in args.bodies.split(",") if b]
    for s in settings:
        if s not in SETTINGS:
            parser.error(f"unknown setting {s!r} (known: {', '.join(SETTINGS)})")
    for b in bodies:
        if b not in BODIES:
            parser.error(f"unknown body {b!r} (known: {', '.join(BODIES)})")
    clips = [(p, p.stem) for p in sorted(args.data.glob("*.bvh"))]
    clips += [(p, f"wide/{p.stem}") for p in sorted((args.data / "wide").glob("*.bvh"))]
    clips = [(p, rig) for p, rig in clips if fnmatch.fnmatch(p.name, args.clips) or fnmatch.fnmatch(rig, args.clips)
             or fnmatch.fnmatch(f"{rig}.bvh", args.clips)]
    if not clips:
        raise SystemExit(f"no clips in {args.data} match {args.clips!r}")

    import mocap_exaggerate

    started = time.perf_counter()
    print(f"mocap_exaggerate from {Path(mocap_exaggerate.__file__).parent}")
    print(f"{len(clips)} rigs; settings {', '.join(settings)}; bodies {', '.join(bodies)}; "
          f"{'first ' + str(args.frames) + ' frames' if args.frames else 'every frame'}; distance "
          f"{'every frame' if args.distance_step == 1 else f'every {args.distance_step}th frame + worst stretch'}")
    print("Targets: " + "; ".join(f"{k} {text}" for k, text in TARGETS))
    print("(% of edges past 1.5x / 2x bind length at some frame; worst edge ratio @ frame; dist = farthest point of "
          "the skeleton's links from the body (vertices and points along its edges), in heights, @ frame; rest = "
          "the same at the bind pose; ratio = dist / rest; grow = largest increase of one point's distance over its "
          "rest distance, in heights; /cap = dist / the captured row's dist)")
    print(HEADER, flush=True)
    tasks = [(str(p), rig, settings, bodies, args.frames, args.distance_step) for p, rig in clips]
    rows: list[dict] = []
    if args.jobs > 1:
        from multiprocessing import get_context

        with get_context("fork").Pool(args.jobs) as pool:
            for got in pool.imap(measure_rig, tasks):  # in order: deterministic
                rows += got
                print("\n".join(row_line(r) for r in got), flush=True)
    else:
        for task in tasks:
            got = measure_rig(task)
            rows += got
            print("\n".join(row_line(r) for r in got), flush=True)

    checked = targets(rows)
    print("\nTargets per rig (T1-T3: 2x share minus its reference's, points; T4: worst default-body ratio)")
    print(f"{'rig':44s} " + " ".join(f"{k:>13s}" for k, _ in TARGETS))
    tally = {k: [0, 0] for k, _ in TARGETS}
    for rig, checks in checked.items():
        cells = []
        for key, _ in TARGETS:
            c = checks[key]
            if c["pass"] is None:
                cells.append(f"{'-':>13s}")
                continue
            tally[key][0 if c["pass"] else 1] += 1
            cells.append(f"{c['value']:+7.3f} {'PASS' if c['pass'] else 'FAIL'}" if key != "T4"
                         else f"{c['value']:7.3f} {'PASS' if c['pass'] else 'FAIL'}")
        extra = f"  ({checks['errors']} rows errored)" if "errors" in checks else ""
        versus = checks["T4_vs_captured"]
        print(f"{rig[:44]:44s} " + " ".join(cells) + (f"  (T4 vs captured {versus:.2f})" if versus else "") + extra)
    print("passed: " + ", ".join(f"{k} {p}/{p + f}" for k, (p, f) in tally.items()))

    lines = summary(rows)
    print("\nSummary over rigs: worst / median (edge shares in %; ratio = dist / rest; /cap = dist / captured's)")
    print(f"{'setting':19s} {'body':9s} {'rigs':>4s} {'>1.5x%':>15s} {'>2x%':>15s} {'ratio':>11s} {'grow':>13s} "
          f"{'/cap':>11s}  worst rig (>2x; ratio)")

    def pair(s: dict, key: str, scale: float, fmt: str, width: int) -> str:
        if key not in s:
            return f"{'-':>{width}s}"
        return f"{format(scale * s[key]['worst'], fmt)}/{format(scale * s[key]['median'], fmt)}".rjust(width)

    for s in lines:
        print(f"{s['setting']:19s} {s['body']:9s} {s['rigs']:4d} {pair(s, 'over_1_5', 100, '.3f', 15)} "
              f"{pair(s, 'over_2', 100, '.3f', 15)} {pair(s, 'ratio', 1, '.2f', 11)} {pair(s, 'grow', 1, '.3f', 13)} "
              f"{pair(s, 'vs_captured', 1, '.2f', 11)}  {s['over_2']['worst_rig']}; {s['ratio']['worst_rig']}")
    seconds = time.perf_counter() - started
    errors = sum(1 for r in rows if "error" in r)
    print(f"\n{len(rows)} rows ({errors} errors) in {seconds:.0f} s with {args.jobs} job(s)")
    if args.json:
        timings = {f"{r['rig']}|{r['setting']}|{r['body']}": r.pop("seconds") for r in rows if "seconds" in r}
        data = {"code": str(Path(mocap_exaggerate.__file__).parent), "settings": settings, "bodies": bodies,
                "frames": args.frames or None, "distance_step": args.distance_step, "along": list(ALONG),
                "targets": dict(TARGETS), "rows": rows, "checks": checked, "summary": lines,
                "timings": {"total": seconds, "rows": timings}}
        args.json.write_text(json.dumps(data, indent=1) + "\n")


if __name__ == "__main__":
    main()
