"""Hostile and careless use, as a real process: one line on stderr, the right exit code, nothing lost.

Every case runs ``mocap-exaggerate`` in a new process on a copy of a sample
clip and checks: the exit code; for a failure, exactly one line on stderr
starting with ``Error:`` and no traceback; the input files unchanged;
nothing written outside the output folder; and for a failure, the output
folder as it was (not even created). The cases are the ones a review found
(issue 9) plus their neighbours.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from .helpers import SAMPLE_DIR

CLIP = SAMPLE_DIR / "cmu_09_01_run_daz.bvh"
FAST = ["--subjoints", "2"]


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *map(str, args)],
                          capture_output=True, text=True, timeout=120, cwd=cwd)


def snapshot(folder):
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.rglob("*"))}


# ---------------------------------------------------------------------------- files for the attacks


def npz(path, **arrays):
    base = {"vertices": np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
            "faces": np.array([[0, 1, 2]]), "joint_names": np.array(["hip"]),
            "joints": np.zeros((3, 1), dtype=np.int64), "weights": np.ones((3, 1))}
    base.update(arrays)
    np.savez(path, **{k: v for k, v in base.items() if v is not None})
    return path


def glb_with(path, change):
    """Our own GLB of the clip (original skeleton, in its units), its JSON edited by ``change``."""
    done = run("exaggerate", CLIP, "-o", path.parent / "made", "--skeleton", "original", "--units", "m", *FAST)
    assert done.returncode == 0, done.stderr
    data = (path.parent / "made" / f"{CLIP.stem}.glb").read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20 : 20 + length])
    change(document)
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    rest = data[20 + length :]
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 20 + len(text) + len(rest)) + struct.pack("<I4s", len(text), b"JSON")
                     + text + rest)
    return path


def chain_bvh(path, depth):
    lines = ["HIERARCHY", "ROOT J0", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    for i in range(1, depth):
        lines += [f"JOINT J{i}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * depth
    values = " ".join(["0.5"] * (6 + 3 * (depth - 1)))
    lines += ["MOTION", "Frames: 3", "Frame Time: 0.0333333"] + [values] * 3
    path.write_text("\n".join(lines) + "\n")
    return path


def edited_clip(path, edit):
    path.write_bytes(edit(CLIP.read_bytes()))
    return path


def first_motion_value(data: bytes, new: bytes) -> bytes:
    head, _, body = data.partition(b"Frame Time:\t0.00833333\n")
    first, _, rest = body.partition(b" ")
    return head + b"Frame Time:\t0.00833333\n" + new + b" " + rest


# ---------------------------------------------------------------------------- the cases

# Each case: id -> function(tmp, clip, out) returning (args, expected exit code, words expected in the error line).
def _fifo(folder, name):
    """A FIFO: reading it blocks until something writes (a clip, a config, a skin once hung the command)."""
    import os

    path = folder / name
    os.mkfifo(path)
    return path


def _big_number_toml(folder):
    path = folder / "big.toml"
    path.write_text("[extrapolate]\nomega = " + "9" * 5000 + "\n")
    return path


def _big_number_trails(folder):
    path = folder / "big.json"
    path.write_text('{"trails": [{"limb": "left_arm", "frames": [' + "9" * 5000 + "]}]}")
    return path


def _frames_over_the_cap(folder, clip):
    path = folder / "long.bvh"
    path.write_bytes(clip.read_bytes().replace(b"Frames:\t149", b"Frames:\t600000", 1))
    return path


def _zip_bomb(folder):
    """A 2 MB .npz that declares 2 GB of zeros (it once filled 6.2 GB before a refusal)."""
    import zipfile

    path = folder / "bomb.npz"
    header = b"\x93NUMPY\x01\x00" + b"{'descr': '<f8', 'fortran_order': False, 'shape': (90000000, 3), }".ljust(118) + b"\n"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        with archive.open("vertices.npy", "w", force_zip64=True) as member:
            member.write(header)
            for _ in range(128):
                member.write(bytes(1 << 24))
    return path


def _lying_npy(folder):
    """An .npz whose array header declares 24 TB in a 1 kB file (a MemoryError traceback once)."""
    import io
    import zipfile

    path = folder / "liar.npz"
    header = b"\x93NUMPY\x01\x00" + b"{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 3), }".ljust(118) + b"\n"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("vertices.npy", header + bytes(64))
        for name in ("faces", "joint_names", "weights"):
            buffer = io.BytesIO()
            np.save(buffer, np.zeros(3))
            archive.writestr(f"{name}.npy", buffer.getvalue())
    return path


def _bad_deflate(folder):
    """An .npz whose compressed member is garbage (zlib's own error, once a traceback)."""
    import zipfile

    good = npz(folder / "good.npz")
    data = bytearray(good.read_bytes())
    with zipfile.ZipFile(good) as archive:
        first = archive.infolist()[0]
    start = first.header_offset + 30 + len(first.filename) + len(first.extra)
    path = folder / "deflate.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in ("vertices", "faces", "joint_names", "joints", "weights"):
            archive.writestr(f"{name}.npy", b"x" * 400)
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        first = archive.infolist()[0]
    start = first.header_offset + 30 + len(first.filename) + len(first.extra)
    data[start:start + first.compress_size] = b"\xff" * first.compress_size
    path.write_bytes(bytes(data))
    (folder / "good.npz").unlink()
    return path


CASES = {
    # 1. the input is never overwritten
    "trails onto the input": lambda t, c, o: (["exaggerate", c, "-o", o, "--stretch", "left_arm:20-60:2", "--trails", c,
                                               "--overwrite"], 2, "input"),
    "preview onto the input": lambda t, c, o: (["preview", c, "-o", c, "--overwrite"], 2, "png"),
    "preview onto the input named png": lambda t, c, o: (_preview_onto(_renamed(c, "clip.png")), 2, "input"),
    "outputs onto the input": lambda t, c, o: (["exaggerate", c, "-o", c.parent, "--overwrite"], 2, "input"),
    "path file onto an output": lambda t, c, o: (["exaggerate", c, "-o", o, "--path-file",
                                                  _trails(t, o / "clip.json"), "--overwrite"], 2, "input"),
    # 2. names stay in their folder
    "name climbs out": lambda t, c, o: (["exaggerate", c, "-o", o, "--name", "../../etc/x"], 2, "name"),
    "name absolute": lambda t, c, o: (["exaggerate", c, "-o", o, "--name", "/tmp/x"], 2, "name"),
    "name with a folder": lambda t, c, o: (["exaggerate", c, "-o", o, "--name", "a/b"], 2, "name"),
    "name too long": lambda t, c, o: (["exaggerate", c, "-o", o, "--name", "n" * 250], 2, "name"),
    # 3. a folder in the way
    "a folder named like an output": lambda t, c, o: (["exaggerate", c, "-o", _folder(o / "clip.glb"), "--overwrite"],
                                                      2, "folder"),
    "output is a file": lambda t, c, o: (["exaggerate", c, "-o", c], 2, "not a folder"),
    # (was exit 1 from the write, "Not a directory", after the whole run)
    "output folder under a file": lambda t, c, o: (["exaggerate", c, "-o", c / "sub"], 2, "clip.bvh exists and is not a folder"),
    "several clips' folder under a file": lambda t, c, o: (["exaggerate", c, c, "-o", c / "sub" / "deeper"], 2,
                                                           "clip.bvh exists and is not a folder"),
    # 4. values the options accept, files the tool reads
    "sigma 1e9 s": lambda t, c, o: (["exaggerate", c, "-o", o, "--sigma", "1e9"], 2, "sigma"),
    "sigma 1e9 frames": lambda t, c, o: (["exaggerate", c, "-o", o, "--sigma", "1e9f"], 2, "sigma"),
    "sigma 1e400": lambda t, c, o: (["exaggerate", c, "-o", o, "--sigma", "1e400"], 2, "sigma"),
    "sigma 30 s on a short clip": lambda t, c, o: (["exaggerate", c, "-o", o, "--sigma", "30s"], 2, "sigma"),
    "sigma 100000 frames": lambda t, c, o: (["exaggerate", c, "-o", o, "--sigma", "100000f"], 2, "sigma"),
    "fps 1e-300": lambda t, c, o: (["exaggerate", c, "-o", o, "--fps", "1e-300"], 2, "fps"),
    "fps 0.001": lambda t, c, o: (["exaggerate", c, "-o", o, "--fps", "0.001"], 2, "fps"),
    "info fps 1e6": lambda t, c, o: (["info", c, "--fps", "1e6"], 2, "fps"),
    "fps nan": lambda t, c, o: (["exaggerate", c, "-o", o, "--fps", "nan"], 2, "fps"),
    "omega inf": lambda t, c, o: (["exaggerate", c, "-o", o, "--omega", "inf"], 2, "omega"),
    "stretch scale -2 (told what a scale must be, as 6 is)": lambda t, c, o: (
        ["exaggerate", c, "-o", o, "--stretch", "left_arm:20-60:-2"], 2, "scale must be a number in [0, 5]"),
    "stretch scale nan": lambda t, c, o: (["exaggerate", c, "-o", o, "--stretch", "left_arm:20-60:nan"], 2,
                                          "scale must be a number in [0, 5]"),
    "max speed -1 (0 is no limit, and said so)": lambda t, c, o: (
        ["exaggerate", c, "-o", o, "--set", "extrapolate.max_speed=-1"], 2, "must be 0 (no limit) or a number in [1, 100]"),
    "sub-link length 1e-9": lambda t, c, o: (["exaggerate", c, "-o", o, "--sublink-length", "1e-9"], 2, "sublink"),
    "sub-link length 0%": lambda t, c, o: (["exaggerate", c, "-o", o, "--sublink-length", "0%"], 2, "sublink"),
    "bvh positions unknown": lambda t, c, o: (["exaggerate", c, "-o", o, "--bvh-positions", "sideways"], 2,
                                             "bvh-positions"),
    "bvh positions 100,000 characters, quoted short": lambda t, c, o: (
        ["exaggerate", c, "-o", o, "--bvh-positions", "p" * 100_000], 2, "(100"),
    "bvh positions in a config": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                                   _bytes(t / "p.toml", b'[output]\nbvh_positions = 7\n')], 2,
                                                  "output.bvh_positions"),
    "preserve volume not a flag in a config": lambda t, c, o: (
        ["exaggerate", c, "-o", o, "--config", _bytes(t / "p.toml", b'[output]\npreserve_volume = "yes"\n')], 2,
        "output.preserve_volume"),
    "preserve volume given a value": lambda t, c, o: (["exaggerate", c, "-o", o, "--preserve-volume=maybe"], 2,
                                                      "preserve-volume"),
    "config not UTF-8": lambda t, c, o: (["exaggerate", c, "-o", o, "--config", _bytes(t / "p.toml", b"\xff\xfe[x]")],
                                         2, "UTF-8"),
    "config nested 5000 deep": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                                 _bytes(t / "p.toml", b"a = " + b"[" * 5000 + b"]" * 5000)], 2, "TOML"),
    "config is a folder": lambda t, c, o: (["exaggerate", c, "-o", o, "--config", _folder(t / "conf")], 2,
                                           "directory"),
    "path file with trails 5": lambda t, c, o: (["exaggerate", c, "-o", o, "--path-file",
                                                 _bytes(t / "e.json", b'{"trails": 5}')], 2, "trails"),
    "path file with points of 1e300": lambda t, c, o: (["exaggerate", c, "-o", o, "--path-file", _bytes(
        t / "e.json", json.dumps({"trails": [{"limb": "left_arm", "frames": [20, 21],
                                               "exaggerated": [[1e300, 0, 0], [0, 0, 0]]}]}).encode())], 2, "trail"),
    "root position 1e300": lambda t, c, o: (["exaggerate", edited_clip(t / "big.bvh", lambda d: first_motion_value(
        d, b"1e300")), "-o", o], 2, "out of range"),
    "digit separators": lambda t, c, o: (["exaggerate", edited_clip(t / "sep.bvh", lambda d: first_motion_value(
        d, b"1_000")), "-o", o], 2, "'1_000'"),
    "hierarchy 5000 deep": lambda t, c, o: (["exaggerate", chain_bvh(t / "deep.bvh", 5000), "-o", o], 2, "deep"),
    "skin npz with string weights": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", weights=np.array([["a"], ["b"], ["c"]]))], 2, "skin"),
    "skin npz joint 999": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", joints=np.full((3, 1), 999))], 2, "joint indices"),
    "skin npz joint -1": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", joints=np.full((3, 1), -1))], 2, "joint indices"),
    "skin npz NaN vertices": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", vertices=np.full((3, 3), np.nan))], 2, "vertex"),
    "skin npz faces out of range": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", faces=np.array([[0, 1, 7]]))], 2, "face"),
    "skin npz negative faces": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", faces=np.array([[0, 1, -2]]))], 2, "face"),
    "skin npz negative weights": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", weights=-np.ones((3, 1)))], 2, "weights"),
    "skin npz NaN weights": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", weights=np.full((3, 1), np.nan))], 2, "weights"),
    "skin npz empty mesh": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(
        t / "s.npz", vertices=np.zeros((0, 3)), faces=np.zeros((0, 3), int), joints=np.zeros((0, 1), int),
        weights=np.zeros((0, 1)))], 2, "no vertices"),
    "skin npz pickled array": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _pickled(t / "s.npz")], 2, "skin"),
    "skin npz truncated": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _cut(npz(t / "s.npz"))], 2, "skin"),
    "skin npz bad CRC": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _bad_crc(npz(t / "s.npz"))], 2, "skin"),
    "skin glb accessor past its buffer": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", glb_with(
        t / "s.glb", lambda d: d["accessors"][0].update(count=10**9))], 2, "accessor"),
    "skin glb negative stride (crashed the process)": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", glb_with(
        t / "s.glb", lambda d: d["bufferViews"][d["accessors"][0]["bufferView"]].update(byteStride=-64))],
        2, "accessor"),
    "skin glb SHORT joints": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", glb_with(
        t / "s.glb", _short_joints)], 2, "skin"),
    "skin glb skin index out of range": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", glb_with(
        t / "s.glb", lambda d: next(n for n in d["nodes"] if "skin" in n).update(skin=7))], 2, "skin"),
    "skin gltf buffer outside its folder": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _gltf(
        t, "../../../../../etc/hostname")], 2, "outside"),
    "skin gltf absolute buffer": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _gltf(t, "/etc/hostname")],
                                                  2, "outside"),
    # 6. wrong output with exit 0 before
    "delta 1e-300 runs and says so": lambda t, c, o: (["exaggerate", c, "-o", o, "--delta", "1e-300", *FAST], 0, ""),
    # 8. files other tools write
    "CR-only line ends": lambda t, c, o: (["exaggerate", edited_clip(t / "mac.bvh", lambda d: d.replace(b"\n", b"\r")),
                                           "-o", o, *FAST], 0, ""),
    "a 500-level chain": lambda t, c, o: (["exaggerate", chain_bvh(t / "chain.bvh", 500), "-o", o, "--no-glb",
                                           "--subjoints", "1"], 0, ""),
    # usage
    "unknown option": lambda t, c, o: (["exaggerate", c, "-o", o, "--omgea", "3"], 2, "--omgea"),
    "missing input": lambda t, c, o: (["exaggerate", "-o", o], 2, "IN.bvh"),
    "no such clip": lambda t, c, o: (["exaggerate", t / "none.bvh", "-o", o], 2, "no such file"),
    "a folder as the clip": lambda t, c, o: (["exaggerate", t, "-o", o], 2, "folder"),
    "unknown preset": lambda t, c, o: (["exaggerate", c, "-o", o, "--preset", "wild"], 2, "preset"),
    "bad weight": lambda t, c, o: (["exaggerate", c, "-o", o, "--weight", "hip=lots"], 2, "weight"),
    "unknown joint weight": lambda t, c, o: (["exaggerate", c, "-o", o, "--weight", "Tail=2"], 2, "Tail"),
    "stretch outside the clip": lambda t, c, o: (["exaggerate", c, "-o", o, "--stretch", "left_arm:100-900:2"],
                                                 2, "frames"),
    # targets and contacts (issue 10)
    "target on an unknown joint": lambda t, c, o: (["exaggerate", c, "-o", o, "--target", "Tail@50"], 2, "Tail"),
    "target outside the clip": lambda t, c, o: (["exaggerate", c, "-o", o, "--target", "rFoot@9999"], 2, "outside"),
    "target in the rest pose": lambda t, c, o: (["exaggerate", c, "-o", o, "--target", "rFoot@1"], 2, "rest-pose"),
    "target on a knee": lambda t, c, o: (["exaggerate", c, "-o", o, "--target", "rShin@50"], 2, "not an end effector"),
    "target with two numbers": lambda t, c, o: (["exaggerate", c, "-o", o, "--target", "rFoot@50=1,2"], 2, "x,y,z"),
    "target at infinity": lambda t, c, o: (["exaggerate", c, "-o", o, "--target", "rFoot@50=1e999,0,0"], 2, "finite"),
    "target without a frame": lambda t, c, o: (["exaggerate", c, "-o", o, "--target", "rFoot"], 2, "JOINT@FRAME"),
    "contacts on a knee": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                            _text(t / "c.toml", '[contacts]\njoints = ["lShin"]\n')], 2, "lShin"),
    "contact speed negative": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                                _text(t / "c.toml", "[contacts]\nspeed = -1\n")], 2, "speed"),
    "unknown anchor": lambda t, c, o: (["exaggerate", c, "-o", o, "--anchor", "moon"], 2, "--anchor"),
    "speed limit below 1": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                             _text(t / "c.toml", "[extrapolate]\nmax_speed = 0.5\n")], 2, "max_speed"),
    "negative smoothing": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                            _text(t / "c.toml", '[extrapolate]\nsmooth = "-1s"\n')], 2, "smooth"),
    "smoothing a day long": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                              _text(t / "c.toml", '[correct]\nsmooth = "86400s"\n')], 2, "smooth"),
    "torso over 1": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                      _text(t / "c.toml", "[correct]\ntorso = 2\n")], 2, "torso"),
    "accent speed not a number": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                                   _text(t / "c.toml", '[correct]\naccent_speed = "fast"\n')], 2, "accent_speed"),
    "strike rate NaN": lambda t, c, o: (["exaggerate", c, "-o", o, "--auto-stretch", "--config",
                                         _text(t / "c.toml", "[auto_stretch]\nmin_rise = nan\n")], 2, "min_rise"),
    "old strike key": lambda t, c, o: (["exaggerate", c, "-o", o, "--config",
                                        _text(t / "c.toml", "[auto_stretch]\nspeed_factor = 3\n")], 2, "speed_factor"),
    # issue 28: every input bounded, no traceback
    "a FIFO as the clip": lambda t, c, o: (["exaggerate", _fifo(t, "take.bvh"), "-o", o], 2, "is a FIFO"),
    "a device as the clip": lambda t, c, o: (["exaggerate", "/dev/zero", "-o", o], 2, "is a device"),
    "a FIFO as the config": lambda t, c, o: (["exaggerate", c, "-o", o, "--config", _fifo(t, "p.toml")], 2, "FIFO"),
    "a device as the config": lambda t, c, o: (["exaggerate", c, "-o", o, "--config", "/dev/zero"], 2, "device"),
    "a FIFO as the skin": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _fifo(t, "s.npz")], 2, "FIFO"),
    "a FIFO as the joint map": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", npz(t / "s.npz"),
                                                 "--joint-map", _fifo(t, "j.map")], 2, "FIFO"),
    "a FIFO as the path file": lambda t, c, o: (["exaggerate", c, "-o", o, "--path-file", _fifo(t, "p.json")],
                                                2, "FIFO"),
    "a 5,000-digit number in a config": lambda t, c, o: (["exaggerate", c, "-o", o, "--config", _big_number_toml(t)],
                                                         2, "4300 digits"),
    "a 5,000-digit frame": lambda t, c, o: (["exaggerate", c, "-o", o, "--target", "lHand@" + "9" * 5000], 2,
                                            "5000 digits"),
    "a 5,000-digit stretch end": lambda t, c, o: (["exaggerate", c, "-o", o, "--stretch",
                                                   "left_arm:10-" + "9" * 5000 + ":2"], 2, "5000 digits"),
    "a 5,000-digit number in a path file": lambda t, c, o: (["exaggerate", c, "-o", o, "--path-file",
                                                             _big_number_trails(t)], 2, "4,300 digits"),
    "frames past the cap": lambda t, c, o: (["exaggerate", _frames_over_the_cap(t, c), "-o", o], 2,
                                            "at most 500,000 frames"),
    "a zip bomb as the skin": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _zip_bomb(t)], 2, "unpacks to"),
    "an array header that lies": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _lying_npy(t)], 2,
                                                  "not a readable .npz"),
    "a broken deflate stream": lambda t, c, o: (["exaggerate", c, "-o", o, "--skin", _bad_deflate(t)], 2,
                                                "not a readable .npz"),
    "a scheduler address without a port": lambda t, c, o: (["batch", t, o, "--scheduler", "tcp://localhost"], 2,
                                                           "with its port"),
    "an inproc scheduler": lambda t, c, o: (["batch", t, o, "--scheduler", "inproc://x:1"], 2, "inproc"),
    "a tls scheduler without certificates": lambda t, c, o: (["batch", t, o, "--scheduler", "tls://127.0.0.1:8786"],
                                                             2, "certificates"),
    "a ucx scheduler": lambda t, c, o: (["batch", t, o, "--scheduler", "ucx://127.0.0.1:8786"], 2, "ucx"),
    "an input named too long for an output": lambda t, c, o: (["exaggerate", _renamed(c, "a" * 220 + ".bvh"), "-o", o],
                                                              2, "give another with --name"),
    # The pipeline file is read by its content, so it may have any name: a picture must not land on it.
    "a preview onto its --config": lambda t, c, o: (["preview", c, "--config", _text(t / "cfg.png", OMEGA_3),
                                                     "-o", t / "cfg.png", "--overwrite"], 2, "would overwrite the input"),
    "a compare onto its --config": lambda t, c, o: (["compare", c, "--config", _text(t / "cfg.html", OMEGA_3),
                                                     "-o", t / "cfg.html", "--overwrite", "--omega", "2,3"], 2,
                                                    "would overwrite the input"),

}


OMEGA_3 = "[extrapolate]\nomega = 3\n"


def _copies(folder, count):
    """A folder of ``count`` copies of the sample clip (a batch's library)."""
    folder.mkdir()
    for index in range(count):
        (folder / f"clip{index:02}.bvh").write_bytes(CLIP.read_bytes())
    return folder


def _text(path, text):
    path.write_text(text)
    return path


def _preview_onto(clip):
    return ["preview", clip, "-o", clip, "--overwrite"]


def _renamed(clip, name):
    target = clip.parent / name
    clip.rename(target)
    return target


def _folder(path):
    path.mkdir(parents=True, exist_ok=True)
    return path.parent if path.suffix == ".glb" else path


def _bytes(path, data):
    path.write_bytes(data)
    return path


def _trails(tmp, target):
    """A valid path file that lives where an output would be written."""
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps({"trails": [{"limb": "left_arm", "frames": [20, 21],
                                              "exaggerated": [[0, 0, 0], [1, 1, 1]]}]}))
    return target


def _pickled(path):
    np.savez(path, vertices=np.zeros((3, 3)), faces=np.array([[0, 1, 2]]), joint_names=np.array(["hip"]),
             joints=np.zeros((3, 1), int), weights=np.array([[object()]] * 3, dtype=object))
    return path


def _cut(path):
    path.write_bytes(path.read_bytes()[:200])
    return path


def _bad_crc(path):
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo("vertices.npy")
    data[info.header_offset + 30 + len(info.filename) + 100] ^= 0xFF  # inside the stored array data
    path.write_bytes(bytes(data))
    return path


def _short_joints(document):
    attributes = document["meshes"][0]["primitives"][0]["attributes"]
    document["accessors"][attributes["JOINTS_0"]]["componentType"] = 5122


def _gltf(tmp, uri):
    path = tmp / "skin.gltf"
    path.write_text(json.dumps({
        "asset": {"version": "2.0"}, "buffers": [{"uri": uri, "byteLength": 64}],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 0, "WEIGHTS_0": 0}}]}],
        "nodes": [{"name": "hip"}, {"mesh": 0, "skin": 0}], "skins": [{"joints": [0]}],
    }))
    return path


@pytest.mark.parametrize("case", sorted(CASES))
def test_one_clean_line_and_nothing_lost(tmp_path, case):
    work = tmp_path / "work"
    work.mkdir()
    clip = work / "clip.bvh"
    clip.write_bytes(CLIP.read_bytes())
    out = tmp_path / "out"
    args, code, words = CASES[case](work, clip, out)
    inputs = snapshot(work)
    outside = {p.name for p in tmp_path.iterdir()}
    out_before = snapshot(out) if out.exists() else None
    done = run(*args, cwd=work)
    assert done.returncode == code, done.stderr
    assert "Traceback" not in done.stderr
    assert snapshot(work) == inputs, "an input (or the folder it is in) changed"
    assert {p.name for p in tmp_path.iterdir()} <= outside | {"out"}, "something was written outside the output folder"
    if code:
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("Error: "), done.stderr
        assert len(lines[0]) < 1000, lines[0][:200]  # a long value is quoted short
        assert words.lower() in lines[0].lower(), lines[0]
        assert (snapshot(out) if out.exists() else None) == out_before, "a refused run wrote into the output folder"


def test_a_batch_never_writes_over_the_pipeline_file_it_was_given(tmp_path):
    """Rebuilding a library from one of its own pipeline files: the clip whose output that file is
    fails alone, and the file is as it was (it was replaced, with exit 0)."""
    library = tmp_path / "lib"
    library.mkdir()
    (library / "clip.bvh").write_bytes(CLIP.read_bytes())
    (library / "jump.bvh").write_bytes((SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh").read_bytes())
    out = tmp_path / "out"
    assert run("batch", library, out, "-j", "1", "-q", "--omega", "3", *FAST).returncode == 0
    given = out / "clip.pipeline.toml"
    before = given.read_bytes()
    done = run("batch", library, out, "-j", "1", "--config", given, "--overwrite", "--omega", "2", *FAST)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert f"would overwrite the input {given}" in done.stderr
    assert given.read_bytes() == before
    assert "--omega 2" not in before.decode() and "omega = 2.0" in (out / "jump.pipeline.toml").read_text()


def test_a_tiny_delta_reports_the_frames_it_could_not_correct(tmp_path):
    done = run("exaggerate", CLIP, "-o", tmp_path, "--delta", "1e-300", "--max-iter", "50", *FAST)
    assert done.returncode == 0, done.stderr
    report = json.loads((tmp_path / f"{CLIP.stem}.json").read_text())["result"]["correct"]
    assert 1 <= report["iterations"] <= 50 and report["unconverged_frames"] > 0


# ---------------------------------------------------------------------------- fuzzing

from click.testing import CliRunner  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from mocap_exaggerate.core.errors import MocapError  # noqa: E402
from mocap_exaggerate.io.bvh import read_bvh  # noqa: E402
from mocap_exaggerate_cli.main import cli  # noqa: E402


def _short_clip() -> bytes:
    """The sample clip cut to 30 frames: quick to run, every part of the format present."""
    data = CLIP.read_bytes()
    head, _, body = data.partition(b"MOTION")
    lines = body.splitlines()[1:]
    return head + b"MOTION\nFrames: 30\n" + lines[1] + b"\n" + b"\n".join(lines[2:32]) + b"\n"


SHORT = _short_clip()
TOKENS = [b"{", b"}", b"JOINT", b"End Site", b"OFFSET", b"CHANNELS 3", b"MOTION", b"Frames: 9", b"nan", b"1e999",
          b"-", b"\t", b"\r", b"\n", b"\x00", b"\xff", b"1_0", b"0x10", b"9" * 400]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_mangled_bvh_bytes_read_or_fail_with_one_input_error(data):
    clip = bytearray(SHORT)
    for _ in range(data.draw(st.integers(1, 4))):
        kind = data.draw(st.sampled_from(["flip", "cut", "insert", "delete"]))
        at = data.draw(st.integers(0, len(clip)))
        if kind == "flip" and at < len(clip):
            clip[at] = data.draw(st.integers(0, 255))
        elif kind == "cut":
            del clip[at:]
        elif kind == "insert":
            clip[at:at] = data.draw(st.sampled_from(TOKENS))
        else:
            del clip[at : at + data.draw(st.integers(1, 40))]
    try:
        motion, _ = read_bvh(bytes(clip))
    except MocapError as error:
        assert "\n" not in str(error) and str(error).startswith("<bytes>")
        return
    assert np.all(np.isfinite(motion.local_positions)) and np.all(np.isfinite(motion.local_rotations))


NUMBERS = st.sampled_from(["0", "-1", "1e-300", "1e300", "nan", "inf", "-inf", "1e9", "3", "0.5", "abc", "", "1_0"])
OPTIONS = {
    "--sigma": st.sampled_from(["0.2s", "0f", "1e9f", "-1s", "1e400", "18 f", "ms", "0.05", "nan"]),
    "--omega": NUMBERS, "--threshold": NUMBERS, "--delta": NUMBERS, "--max-stretch": NUMBERS,
    "--max-iter": st.sampled_from(["1", "0", "-5", "1e3", "100000", "100001"]),
    "--subjoints": st.sampled_from(["1", "0", "33", "-1", "x"]),
    "--sublink-length": st.sampled_from(["3%", "0%", "1e-9", "-2", "200%", "1e300", "x%"]),
    "--stiffness": NUMBERS, "--link-stiffness": NUMBERS, "--damping": NUMBERS, "--blend": NUMBERS,
    "--fps": NUMBERS, "--tpose": st.sampled_from(["auto", "drop", "keep", "maybe"]),
    "--weight": st.sampled_from(["hip=0", "left_arm=2", "Left*=11", "=1", "x", "hip=nan", "nothere=1"]),
    "--stretch": st.sampled_from(["left_arm:5-20:2", "left_arm:20-5:2", "left_arm:1-2:6", "wing:1-9:2", "left_arm:0-29:0",
                                  "left_arm:1s-2s:2", "right_leg:3-25:1.5:axes=y:pivot=end:ease_in=0.6,0.2"]),
    "--units": st.sampled_from(["auto", "cm", "furlong"]),
    "--influences": st.sampled_from(["4", "8", "5"]),
    "--name": st.sampled_from(["ok", "../up", "a/b", ".dot", "n" * 300]),
    "--skeleton": st.sampled_from(["sub", "original", "both"]),
    "--bvh-positions": st.sampled_from(["standard", "input", "add", ""]),
}


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(picked=st.dictionaries(st.sampled_from(sorted(OPTIONS)), st.just(None), max_size=4), data=st.data())
def test_option_values_end_in_success_or_one_line(tmp_path_factory, picked, data):
    folder = tmp_path_factory.mktemp("fuzz")
    clip = folder / "clip.bvh"
    clip.write_bytes(SHORT)
    args = ["exaggerate", str(clip), "-o", str(folder / "out"), "--no-glb", "--subjoints", "2"]
    for option in picked:
        args += [option, data.draw(OPTIONS[option], label=option)]
    result = CliRunner().invoke(cli, args)
    assert result.exception is None or isinstance(result.exception, SystemExit), (args, result.exception)
    assert result.exit_code in (0, 2), (args, result.stderr)
    if result.exit_code:
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("Error: "), (args, result.stderr)
        assert not (folder / "out").exists(), args
    assert clip.read_bytes() == SHORT
    assert {p.name for p in folder.iterdir()} <= {"clip.bvh", "out"}, args


# ---------------------------------------------------------------------------- every option, hostile values

#: Values no option should choke on: empty, not numbers, out of range, huge, long, two lines, not UTF-8.
HOSTILE = [b"", b"nan", b"inf", b"-1", b"1e309", b"x" * 2000, b"a\nb", b"\xff\xfe"]
#: Where each command starts from (quick: a short clip, two sub-links, no GLB where it can).
BASE = {"exaggerate": ["exaggerate", "clip.bvh", "-o", "out", "--no-glb", "--subjoints", "2"],
        "batch": ["batch", "in", "out", "--no-glb", "--subjoints", "2", "-j", "1"],
        "plan": ["plan", "in", "out"],
        "preview": ["preview", "clip.bvh", "-o", "p.png", "--subjoints", "2", "--frames", "1"],
        "info": ["info", "clip.bvh"],
        "compare": ["compare", "clip.bvh", "-o", "g.png", "--omega", "2,3", "--subjoints", "2", "--frames", "1"],
        "tune": ["tune", "clip.bvh", "--subjoints", "2"]}
#: Hostile values an option takes as they are: any text names a folder or a file to write, and a
#: preview may show every second there is.
TAKEN = {("exaggerate", "--output"): {b"nan", b"inf", b"-1", b"1e309", b"a\nb", b"\xff\xfe"},
         ("exaggerate", "--name"): {b"nan", b"inf", b"-1", b"1e309", b"\xff\xfe"},
         ("exaggerate", "--trails"): {b"nan", b"inf", b"-1", b"1e309", b"a\nb", b"\xff\xfe"},
         ("preview", "--seconds"): {b"inf", b"1e309"}, ("compare", "--seconds"): {b"inf", b"1e309"},
         ("compare", "--output"): set(),
         # An empty animation name is none: a glTF's first (and a BVH's one clip).
         ("exaggerate", "--clip"): {b""}, ("info", "--clip"): {b""}}


def _swept_options() -> list:
    """(command, option) for every option of every command; the options a command shares with
    'exaggerate' (the same decorators) are swept there once."""
    import click as _click

    root = _click.Context(cli)
    shared = {(tuple(p.opts), p.help) for p in cli.get_command(root, "exaggerate").params}
    # compare takes a run's options as lists of text, each cell's words parsed as exaggerate's (swept there)
    from mocap_exaggerate_cli.compare import _settings

    theirs = {tuple(p.opts) for p in _settings.params}
    params = []
    for name in BASE:
        for param in cli.get_command(root, name).params:
            if not isinstance(param, _click.Option) or param.name in ("verbose", "quiet", "help"):
                continue
            if name != "exaggerate" and (tuple(param.opts), param.help) in shared:
                continue
            if name == "compare" and tuple(param.opts) in theirs:
                continue
            params.append(pytest.param(name, param.opts[-1], param.is_flag, id=f"{name} {param.opts[-1]}"))
    return params


@pytest.mark.parametrize(("command", "option", "is_flag"), _swept_options())
def test_every_option_refuses_hostile_values_in_one_line(tmp_path, command, option, is_flag):
    import os

    work = tmp_path / "work"
    (work / "in").mkdir(parents=True)
    for target in (work / "clip.bvh", work / "in" / "clip.bvh"):
        target.write_bytes(SHORT)
    values = [b"nan"] if is_flag else HOSTILE  # a flag given a value: --glb=nan
    for value in values:
        words = [option.encode() + b"=" + value] if is_flag else [option.encode(), value]
        before = snapshot(work)
        done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *BASE[command], *words], cwd=work,
                              capture_output=True, timeout=300)
        stderr = os.fsdecode(done.stderr)
        shown = f"{command} {option} {value[:20]!r}: {stderr[:300]}"
        assert "Traceback" not in stderr, shown
        if value in TAKEN.get((command, option), ()):
            assert done.returncode == 0, shown
            for made in sorted(set(snapshot(work)) - set(before), reverse=True):  # cleared for the next value
                path = work / made
                path.unlink() if path.is_file() else path.rmdir()
            continue
        lines = stderr.strip().splitlines()
        assert done.returncode == 2, shown
        assert len(lines) == 1 and lines[0].startswith("Error: ") and len(lines[0]) < 1000, shown
        assert snapshot(work) == before, f"{shown}: a refused run wrote something"


# ---------------------------------------------------------------------------- internal errors

#: Runs the command line in a new process with one function replaced by one that raises
#: RuntimeError: a bug, wherever it is met (an option's callback, the command, a worker thread).
BROKEN = """
import importlib, sys
module, name = sys.argv[1].rsplit(":", 1)
owner = importlib.import_module(module)
*path, attribute = name.split(".")
for part in path:
    owner = getattr(owner, part)
def broken(*args, **kwargs):
    raise RuntimeError("a bug planted by the test")
setattr(owner, attribute, broken)
sys.argv = ["mocap-exaggerate", *sys.argv[2:]]
from mocap_exaggerate_cli.main import main
main()
"""


@pytest.mark.parametrize(("where", "args"), [
    # --set's callback reads its value as TOML
    ("tomllib:loads", ["--set", "springs.blend=0.3"]),
    # the type every path option and argument converts through
    ("mocap_exaggerate_cli.options:FilePath.convert", []),
    # the config, read in the command's body
    ("mocap_exaggerate_cli.options:resolve_config", []),
    # the GLB, built in a worker thread while the BVH is being written
    ("mocap_exaggerate.jobs.outputs:glb_files", []),
    # the BVH's text, written into the set
    ("mocap_exaggerate.jobs.job:iter_bvh", []),
])
def test_an_internal_error_is_one_line_exit_3_and_writes_nothing(tmp_path, where, args):
    clip = tmp_path / "clip.bvh"
    clip.write_bytes(SHORT)
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-c", BROKEN, where, "exaggerate", str(clip), "-o", str(out), *args],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 3, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: internal error (RuntimeError: a bug planted by the test)")
    assert "-vv" in lines[0]
    assert not out.exists(), sorted(p.name for p in out.iterdir())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.bvh"]
    # -vv, before or after the options, shows where it happened.
    done = subprocess.run([sys.executable, "-c", BROKEN, where, "exaggerate", str(clip), "-o", str(out), *args, "-vv"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 3 and "Traceback" in done.stderr and "a bug planted by the test" in done.stderr
    assert done.stderr.strip().splitlines()[-1].startswith("Error: internal error")


# ---------------------------------------------------------------------------- issue 28: the rest


def test_a_closed_standard_output_or_input_is_one_line(tmp_path):
    for args in (["exaggerate", CLIP, "-o", "-"], ["exaggerate", "-", "-o", tmp_path / "out"]):
        # Started with the stream closed (>&- or <&-), as a shell does it.
        closing = "exec 1>&-; " if args[-1] == "-" else "exec 0<&-; "
        words = " ".join(f"'{w}'" for w in map(str, args))
        done = subprocess.run(["sh", "-c", f"{closing}'{sys.executable}' -m mocap_exaggerate_cli.main {words}"],
                              stderr=subprocess.PIPE, text=True, timeout=120)
        assert done.returncode == 2 and "is closed" in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_ctrl_c_in_the_first_moments_is_quiet(tmp_path):
    """From the first line of the command's package on, a Ctrl-C ends it quietly (exit 130). Before that
    line Python is still starting (its site module, runpy finding the package): a Ctrl-C there is
    Python's own, and it says so itself, with no line of ours in what it prints. The command's
    package once imported `signal` first, whose enums take milliseconds: a window of its own."""
    import signal
    import time
    from pathlib import Path

    import mocap_exaggerate
    import mocap_exaggerate_cli

    ours = (str(Path(mocap_exaggerate.__file__).parent) + "/", str(Path(mocap_exaggerate_cli.__file__).parent) + "/")
    quiet = 0
    for delay in (0.01, 0.015, 0.02, 0.03, 0.05, 0.08, 0.2) * 3:
        process = subprocess.Popen([sys.executable, "-m", "mocap_exaggerate_cli.main", "info", str(CLIP)],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        process.send_signal(signal.SIGINT)
        _, said = process.communicate(timeout=60)
        assert not any(folder in said for folder in ours), (delay, said)  # never from a line of ours
        if "Traceback" in said:
            continue  # Python's own start: before the package's first line
        assert process.returncode in (0, 130, -signal.SIGINT), (delay, process.returncode, said)  # 0: it had ended
        quiet += process.returncode == 130
    assert quiet >= 6  # (most presses land in our part: the test would not pass on Python's start alone)


def test_names_with_terminal_escapes_are_shown_escaped(tmp_path):
    clip = tmp_path / "escape.bvh"
    clip.write_bytes(CLIP.read_bytes().replace(b"JOINT lHand", b"JOINT l\x1b[2JHand", 1))
    done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "info", str(clip), "--limbs"],
                          capture_output=True, timeout=120)
    assert b"\x1b" not in done.stdout and b"\x1b" not in done.stderr
    done = run("exaggerate", clip, "-o", tmp_path / "out", "--target", "l\x1b[2JHand@9999", *FAST)
    assert done.returncode == 2 and "\x1b" not in done.stderr and "\\x1b" in done.stderr, done.stderr


def test_a_batch_shows_clip_names_escaped(tmp_path):
    """A clip named with a terminal's escape sequence or a newline: each line of the batch shows the name
    escaped, as the other commands do (the name cleared the screen; a newline split a line in two)."""
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "clear\x1b[2J.bvh").write_bytes(CLIP.read_bytes())
    (folder / "two\nlines.bvh").write_bytes(b"HIERARCHY\nnot a clip\n")
    for quiet in ([], ["-q"]):
        done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", *quiet, "batch", str(folder),
                               str(tmp_path / f"out{len(quiet)}"), "-j", "1", "--no-glb", "--json"],
                              capture_output=True, timeout=300)
        assert done.returncode == 1, done.stderr  # neither converts: one is not a clip, one not a name to write
        assert b"\x1b" not in done.stderr + done.stdout, done.stderr
        lines = done.stderr.decode().splitlines()
        assert any(line.startswith("failed: ") and "two\\nlines.bvh" in line for line in lines), lines
        assert not any(line.startswith("lines.bvh") for line in lines), lines
        assert any(line.startswith("failed: ") and "clear\\x1b[2J.bvh" in line for line in lines), lines
        assert len(done.stdout.splitlines()) == 2  # the JSON lines, one a clip


@pytest.mark.parametrize("elsewhere", [False, True], ids=["one TMPDIR", "two TMPDIRs"])
def test_two_batches_into_one_folder_the_second_is_refused(tmp_path, elsewhere):
    """Also where the second's temporary folder is another (TMPDIR per user, PrivateTmp, containers
    sharing a volume): both ran into one folder, each exit 0, when the lock was a temporary file."""
    import os
    import time

    folder = _copies(tmp_path / "in", 40)
    out = tmp_path / "out"
    first = subprocess.Popen([sys.executable, "-m", "mocap_exaggerate_cli.main", "batch", str(folder), str(out),
                              "-j", "1", "-q"], stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not list(out.glob("*.json")) and time.monotonic() < deadline:  # converting: a clip is done
            time.sleep(0.05)
        assert first.poll() is None
        other = tmp_path / "other tmp"
        other.mkdir()
        env = {**os.environ, "TMPDIR": str(other)} if elsewhere else None
        second = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "batch", str(folder), str(out),
                                 "-j", "1"], capture_output=True, text=True, timeout=120, env=env)
        assert second.returncode == 2 and "another batch is writing into this folder" in second.stderr, second.stderr
    finally:
        _, said = first.communicate(timeout=300)
    assert first.returncode == 0, said
    assert run("batch", folder, out, "-j", "1", "--resume", "-q").returncode == 0  # free again once it ended


def test_a_manifest_nested_a_million_deep_beside_a_clip_fails_nothing(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "a.bvh").write_bytes(CLIP.read_bytes())
    (folder / "a.json").write_text("[" * 1_000_000 + "]" * 1_000_000)
    done = run("batch", folder, tmp_path / "out", "-j", "1", "--resume")
    assert "Traceback" not in done.stderr and done.returncode in (0, 1), done.stderr


def test_a_port_that_does_not_speak_dask_is_refused_within_ten_seconds(tmp_path):
    import socket
    import time

    pytest.importorskip("distributed", reason="Dask distributed is not installed")
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(5)
    port = listener.getsockname()[1]
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "a.bvh").write_bytes(CLIP.read_bytes())
    try:
        start = time.monotonic()
        done = run("batch", tmp_path / "in", tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}")
        took = time.monotonic() - start
    finally:
        listener.close()
    assert done.returncode == 2 and "did not answer as a Dask scheduler" in done.stderr, done.stderr
    assert took < 10 + 5  # the greeting's 8 s and a start-up


def test_a_star_of_many_links_shares_a_vertex_among_its_nearest_links_only():
    from mocap_exaggerate import load_preset
    from mocap_exaggerate.pipeline import run as pipeline_run
    from mocap_exaggerate.rig import skinning

    motion, _ = read_bvh(_star_bvh(300))
    result = pipeline_run(motion, load_preset("cartoon"))
    from mocap_exaggerate.jobs.outputs import base_skin

    skin = base_skin(motion, result)
    links = skinning._link_knots(motion.skeleton, result.hierarchy,
                                 skinning.subjoint_bind_positions(motion.skeleton, result.hierarchy, skin.bind),
                                 per_link=skin.per_link)
    vertex = np.repeat(np.arange(skin.num_vertices), skin.joints.shape[1])
    keep = skin.weights.ravel() > 0
    original = np.array([motion.skeleton.index(n) for n in skin.joint_names])[skin.joints.ravel()][keep]
    pair_entry, _ = skinning._pairs(skin.vertices[vertex[keep]], original, links)
    assert len(pair_entry) <= skinning._NEAREST * len(original)  # quadratic before: 299 links for each
    reweighted = skinning.reweight(skin, motion.skeleton, result.hierarchy)
    assert np.all(np.isfinite(reweighted.weights)) and np.allclose(reweighted.weights.sum(axis=1), 1.0)


def _star_bvh(count: int):
    import math
    import tempfile
    from pathlib import Path

    lines = ["HIERARCHY", "ROOT J0", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    for i in range(1, count):
        angle = 2 * math.pi * i / count
        lines += [f"JOINT J{i}", "{", f"OFFSET {math.cos(angle):.4f} {1 + (i % 7) * 0.1:.4f} {math.sin(angle):.4f}",
                  "CHANNELS 3 Zrotation Xrotation Yrotation", "End Site", "{", "OFFSET 0 1 0", "}", "}"]
    lines += ["}", "MOTION", "Frames: 6", "Frame Time: 0.0333333"]
    lines += [" ".join(["0"] * 6 + [f"{(f * 3 + i) % 20}" for i in range(3 * (count - 1))]) for f in range(6)]
    path = Path(tempfile.mkdtemp()) / "star.bvh"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_clip_over_the_size_limit_is_refused_before_it_is_read(monkeypatch):
    import io

    from mocap_exaggerate.core.errors import InputError
    from mocap_exaggerate.io import files

    with pytest.raises(InputError, match="is over"):
        files.read_stream(io.BytesIO(b"x" * 101), limit=100, what="clip", label="<stdin>")
    assert files.read_stream(io.BytesIO(b"x" * 100), limit=100, what="clip", label="<stdin>") == b"x" * 100


def test_a_stream_is_read_a_piece_at_a_time_never_asked_for_the_whole_limit(monkeypatch, tmp_path):
    """Asked for 1 GiB at once, a stream makes a 1 GiB buffer before it reads a byte (a MemoryError where
    memory is not overcommitted, for every clip): a file is asked for its size and one byte more, a pipe
    for pieces of READ_PIECE, and what they hold is read whole, however the pieces fall."""
    import io

    from mocap_exaggerate.core.errors import InputError
    from mocap_exaggerate.io import files

    class Pipe(io.RawIOBase):  # gives at most 7 bytes a read, as a pipe gives what it has
        def __init__(self, data: bytes) -> None:
            self.data, self.asked = data, []

        def readable(self) -> bool:
            return True

        def read(self, size: int = -1) -> bytes:
            self.asked.append(size)
            piece, self.data = self.data[:min(size, 7)], self.data[min(size, 7):]
            return piece

    monkeypatch.setattr(files, "READ_PIECE", 10)
    pipe = Pipe(bytes(range(95)))
    assert files.read_stream(pipe, limit=100, what="clip", label="<stdin>") == bytes(range(95))
    assert max(pipe.asked) <= 11
    with pytest.raises(InputError, match="is over"):
        files.read_stream(Pipe(b"x" * 101), limit=100, what="clip", label="<stdin>")

    class NonBlocking(Pipe):  # has nothing for a moment: None, as a non-blocking pipe says it
        def read(self, size: int = -1):
            return None if len(self.asked) == 1 and self.asked.append(size) is None else super().read(size)

    with pytest.raises(InputError, match="non-blocking"):  # (its first 7 bytes are not the clip: refused, not cut)
        files.read_stream(NonBlocking(b"HIERARCHY" * 3), limit=100, what="clip", label="<stdin>")
    clip = tmp_path / "clip.bvh"
    clip.write_bytes(b"y" * 5000)
    opened = []
    monkeypatch.setattr(files, "open", lambda path, mode: opened.append(Pipe(clip.read_bytes())) or opened[-1],
                        raising=False)
    assert files.read_limited(clip, limit=1 << 30, what="clip") == b"y" * 5000
    assert opened[0].asked[0] == 5001 and max(opened[0].asked) <= 5001


def test_the_command_keeps_freed_memory_for_long_clips():
    """The command's process takes large blocks from the heap and keeps what is freed (`keep_freed_memory`):
    set once, in the process; left alone where the user set glibc's variables themselves."""
    import os

    if not os.path.exists("/lib/x86_64-linux-gnu/libc.so.6") and not os.path.exists("/usr/lib/libc.so.6"):
        pytest.skip("not glibc")
    code = "from mocap_exaggerate.jobs.memory import keep_freed_memory as k; print(k(), k())"
    clean = {name: value for name, value in os.environ.items() if not name.startswith("MALLOC_")}
    done = subprocess.run([sys.executable, "-c", code], env=clean, capture_output=True, text=True, timeout=60)
    assert done.stdout.split() == ["True", "True"], done.stderr
    done = subprocess.run([sys.executable, "-c", code], env={**clean, "MALLOC_ARENA_MAX": "4"}, capture_output=True,
                          text=True, timeout=60)
    assert done.stdout.split() == ["False", "False"], done.stderr
    from mocap_exaggerate.jobs import memory

    assert memory._KEEP < 2**31  # mallopt takes a C int: 4 GiB was cut to 0 (trim everything) before


def test_dask_workers_get_glibc_thresholds_back():
    import os

    from mocap_exaggerate.jobs import on_dask

    pytest.importorskip("distributed", reason="Dask distributed is not installed")
    if not os.path.exists("/lib/x86_64-linux-gnu/libc.so.6") and not os.path.exists("/usr/lib/libc.so.6"):
        pytest.skip("not glibc")
    done = subprocess.run([sys.executable, "-c", "from mocap_exaggerate.jobs.on_dask import malloc_thresholds as m; "
                           "print(m(), m())"], env={**os.environ, "MALLOC_TRIM_THRESHOLD_": "65536"},
                          capture_output=True, text=True, timeout=60)
    assert done.stdout.split() == ["True", "True"], done.stderr
    assert on_dask.malloc_thresholds() is False or "MALLOC_TRIM_THRESHOLD_" in os.environ  # nothing to do here


def test_a_batchs_json_reader_that_goes_away_stops_it_saying_what_is_not_done(tmp_path):
    """``batch --json | head``: the reader closes standard output; the batch stops as Ctrl-C stops it and
    says so on standard error, with what --resume would finish (it stopped at once, exit 1, saying
    nothing: ten of twelve clips left without a word)."""
    folder = _copies(tmp_path / "in", 12)
    out = tmp_path / "out"
    batch = subprocess.Popen([sys.executable, "-m", "mocap_exaggerate_cli.main", "batch", str(folder), str(out),
                              "-j", "1", "--json", *FAST], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    batch.stdout.readline()  # the first clip's line, then the reader goes away
    batch.stdout.close()
    said = batch.stderr.read()
    assert batch.wait(timeout=300) == 1 and "Traceback" not in said, said
    assert "standard output closed" in said and "not done" in said and "--resume" in said, said
    done = run("batch", folder, out, "-j", "1", "--resume", "-q", *FAST)
    assert done.returncode == 0 and len(list(out.glob("*.bvh"))) == 12, done.stderr


def test_two_runs_into_one_folder_at_once_both_write_their_set(tmp_path):
    """A farm's retry beside its first try, same clip, same folder: both runs finish (one failed with
    "clip.bvh: No such file or directory", the other having taken its live temporaries for a killed
    run's and deleted them), and the set in the folder is whole."""
    from mocap_exaggerate.jobs.job import check_output_set

    out = tmp_path / "out"
    assert run("exaggerate", CLIP, "-o", out, "-q", *FAST).returncode == 0
    for _ in range(3):
        runs = [subprocess.Popen([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(CLIP), "-o",
                                  str(out), "--overwrite", "--omega", omega, "-q", *FAST], stderr=subprocess.PIPE,
                                 text=True) for omega in ("2", "3")]
        said = [process.communicate(timeout=120)[1] for process in runs]
        assert [process.returncode for process in runs] == [0, 0], said
        assert check_output_set(out / f"{CLIP.stem}.json") == []
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]


def test_a_json_reader_gone_before_the_first_clip_is_said_too(tmp_path):
    """The reader is gone before any clip runs, and the first result said is a clip refused by its name:
    the same stop and the same words (it was "Aborted!", exit 130, as if Ctrl-C)."""
    import os

    folder = _copies(tmp_path / "in", 2)
    (folder / "clip00.bvh").rename(folder / "bad\x01name.bvh")
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "batch", str(folder),
                               str(tmp_path / "out"), "-j", "1", "--json", *FAST], stdout=write, stderr=subprocess.PIPE,
                              text=True, timeout=120)
    finally:
        os.close(write)
    assert done.returncode == 1 and "Traceback" not in done.stderr and "Aborted" not in done.stderr, done.stderr
    assert "standard output closed" in done.stderr and "1 file(s) not done" in done.stderr, done.stderr


@pytest.mark.parametrize("greeting", [b"\xff" * 100_000, struct.pack("<QQQ", 1, 1, 2**62), struct.pack("<QQQ", 2**62, 1, 5)],
                         ids=["a flood of bytes", "a size of 1 and a frame of 2**62 bytes", "a size of 2**62"])
def test_a_port_that_sends_what_dask_does_not_is_refused_in_one_line(tmp_path, greeting):
    # Each reached Dask's own reader and ended in an internal error (a struct or "maximum dimension" error, exit 3).
    import socket
    import threading
    import time

    pytest.importorskip("distributed", reason="Dask distributed is not installed")
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(5)
    port = listener.getsockname()[1]

    def serve():
        while True:
            try:
                connection, _ = listener.accept()
            except OSError:
                return
            try:
                connection.sendall(greeting)
            except OSError:
                pass

    threading.Thread(target=serve, daemon=True).start()
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "a.bvh").write_bytes(CLIP.read_bytes())
    try:
        start = time.monotonic()
        done = run("batch", tmp_path / "in", tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}", "--no-glb")
        took = time.monotonic() - start
    finally:
        listener.close()
    assert done.returncode == 2 and "not a Dask scheduler" in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and took < 10 + 5


@pytest.mark.parametrize("option", [["--stretch", "left_leg:1e308s-2:2"], ["--stretch", "left_leg:1-1e308s:2"],
                                    ["--stretch", "left_leg:1-2:2:release=1e308s"], ["--target", "lfoot@1e308s"],
                                    ["--sigma", "9" * 5000 + "f"], ["--set", "correct.max_iter=1e308"],
                                    ["--set", "extrapolate.sigma=" + "9" * 400]])
def test_durations_and_numbers_past_any_float_are_one_short_line(tmp_path, option):
    # 1e308 seconds at 120 fps is past any float: an OverflowError (exit 3) turning it into a frame number; a
    # 309-digit or 5,000-digit number was quoted whole.
    done = run("exaggerate", SAMPLE_DIR / "cmu_16_01_jump_amc2bvh.bvh", "-o", tmp_path / "out", *option)
    assert done.returncode == 2 and done.stderr.startswith("Error:"), done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and len(done.stderr) < 300, done.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def _gltf_skeleton(path, joints: int, *, chain: bool = False, seconds: float = 1.0, uri: str | None = None,
                   turns=((0, 0, 0, 1), (0, 0, 0.6, 0.8))) -> None:
    """A small glTF: a skinned triangle on ``joints`` joints (a star, or a ``chain``), one animation of
    ``seconds``; its buffer a data URI, or the file ``uri`` beside it."""
    import base64

    data, views, accessors = bytearray(), [], []

    def add(values, component, kind):
        values = np.ascontiguousarray(values)
        views.append({"buffer": 0, "byteOffset": len(data), "byteLength": values.nbytes})
        data.extend(values.tobytes())
        while len(data) % 4:
            data.append(0)
        accessors.append({"bufferView": len(views) - 1, "componentType": component, "count": len(values), "type": kind})
        return len(accessors) - 1

    position = add(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), 5126, "VEC3")
    accessors[position].update({"min": [0, 0, 0], "max": [1, 1, 0]})
    weights = add(np.array([[1, 0, 0, 0]] * 3, np.float32), 5126, "VEC4")
    bones = add(np.zeros((3, 4), np.uint16), 5123, "VEC4")
    times = add(np.array([0.0, seconds], np.float32), 5126, "SCALAR")
    accessors[times].update({"min": [0.0], "max": [seconds]})
    turns = add(np.array(turns, np.float32), 5126, "VEC4")
    nodes = [{"mesh": 0, "skin": 0}] + [{"name": f"j{k}", "translation": [0, 1, 0] if k else [0, 0, 0]}
                                         for k in range(joints)]
    for k in range(1, joints):
        nodes[k if chain else 1].setdefault("children", []).append(k + 1)
    buffer = {"byteLength": len(data)}
    buffer["uri"] = uri or "data:application/octet-stream;base64," + base64.b64encode(bytes(data)).decode()
    path.write_text(json.dumps({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}], "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": position, "JOINTS_0": bones, "WEIGHTS_0": weights}}]}],
        "skins": [{"joints": list(range(1, joints + 1))}],
        "animations": [{"name": "a", "samplers": [{"input": times, "output": turns}],
                        "channels": [{"sampler": 0, "target": {"node": joints, "path": "rotation"}}]}],
        "buffers": [buffer], "bufferViews": views, "accessors": accessors}))


def test_a_small_gltf_passes_and_its_caps_are_the_bvh_readers(tmp_path):
    # The glTF reader skipped the joint, depth and joint-frame caps: 2,500 joints converted, a 1,500-deep chain
    # was read, a 50,000-node file took 21 s in pygltflib, 1,999 joints of 390,001 frames asked for 93 GiB.
    ok = tmp_path / "ok.gltf"
    _gltf_skeleton(ok, 5)
    assert run("info", ok).returncode == 0
    for name, joints, chain, seconds, said in (
            ("star.gltf", 2500, False, 1.0, "the skin has 2500 joints; at most 2000"),
            ("chain.gltf", 1500, True, 1.0, "1500 joints deep; at most 1000"),
            ("nodes.gltf", 6000, True, 1.0, "the file has 6,001 nodes; at most 5,000"),
            ("long.gltf", 1999, False, 13000.0, "at most 30,000,000 joints times frames")):
        _gltf_skeleton(tmp_path / name, joints, chain=chain, seconds=seconds)
        done = run("exaggerate", tmp_path / name, "-o", tmp_path / "out")
        assert done.returncode == 2 and said in done.stderr and len(done.stderr.splitlines()) == 1, done.stderr
        assert not (tmp_path / "out").exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_gltf_buffer_is_read_as_every_file_is(tmp_path):
    # A buffer file beside the glTF was read whole, whatever it was: a FIFO blocked for ever, 3 GiB took 3 GB.
    fifo = tmp_path / "fifo.gltf"
    _gltf_skeleton(fifo, 3, uri="pipe.bin")
    os.mkfifo(tmp_path / "pipe.bin")
    sparse = tmp_path / "sparse.gltf"
    _gltf_skeleton(sparse, 3, uri="big.bin")
    with open(tmp_path / "big.bin", "wb") as big:
        big.truncate((1 << 30) + 1)
    for path, said in ((fifo, "is a FIFO, not a glTF buffer"), (sparse, "a glTF buffer is read up to 1 GiB")):
        done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "info", str(path)],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 2 and said in done.stderr and len(done.stderr.splitlines()) == 1, done.stderr


def test_a_bvh_of_more_joints_times_frames_than_a_run_can_hold_is_refused_at_its_frames_line(tmp_path):
    # 100 joints of 400,000 frames (each within its own cap) is 40 million joint-frames, about 24 GB at work.
    path = _star_bvh(100)
    text = path.read_text().replace("Frames: 6", "Frames: 400000")
    (tmp_path / "many.bvh").write_text(text)
    done = run("exaggerate", tmp_path / "many.bvh", "-o", tmp_path / "out")
    assert done.returncode == 2 and "at most 30,000,000 joints times frames" in done.stderr, done.stderr
    line = next(k for k, row in enumerate(text.splitlines(), 1) if row.startswith("Frames:"))
    assert f"many.bvh:{line}:" in done.stderr and not (tmp_path / "out").exists()
    assert run("info", path).returncode == 0  # (the same star of 6 frames reads)


def test_zero_rotation_keys_and_complex_vertices_are_one_line_not_a_warning(tmp_path):
    # All-zero rotation keys printed NumPy's divide warning (three lines, an internal path) before the error;
    # complex vertices were taken with their imaginary part dropped (a ComplexWarning, exit 0).
    zero = tmp_path / "zero.gltf"
    _gltf_skeleton(zero, 3, turns=((0, 0, 0, 0), (0, 0, 0, 0)))
    done = run("info", zero)
    assert done.returncode == 2 and "not all zero" in done.stderr and len(done.stderr.splitlines()) == 1, done.stderr
    skin = tmp_path / "complex.npz"
    np.savez(skin, vertices=np.zeros((3, 3), complex), faces=np.array([[0, 1, 2]]), joint_names=np.array(["Hips"]),
             joints=np.zeros((3, 1), int), weights=np.ones((3, 1)))
    done = run("exaggerate", CLIP, "-o", tmp_path / "out", "--skin", skin)
    assert done.returncode == 2 and "vertices must be real numbers" in done.stderr, done.stderr
    assert len(done.stderr.splitlines()) == 1 and not (tmp_path / "out").exists()


def test_a_long_run_of_digits_in_a_file_name_is_shown_as_the_name_is(tmp_path):
    # Numbers of 40 digits or more are shown short in messages; a file's name is not a number.
    name = "take_" + "1" * 45 + ".bvh"
    (tmp_path / name).write_text("HIERARCHY\nROOT Hips\n{\n")
    done = run("info", tmp_path / name)
    assert done.returncode == 2 and name in done.stderr, done.stderr
