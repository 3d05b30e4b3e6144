"""BVH reading and writing on real clips, with bvhio as an independent oracle."""

import re
import warnings

import bvhio
import numpy as np
import pytest

from mocap_exaggerate.core.errors import InputError
from mocap_exaggerate.io.bvh import format_bvh, read_bvh, save_bvh
from mocap_exaggerate.io.files import OutputExistsError

from .helpers import MALFORMED, SAMPLE_DIR, SIMPLE, all_clip_params, make_bvh, shared, shared_clip_params

# frames, joints, End Sites, channels: from ../shared/data/bvh/SOURCES.md
EXPECTED = {
    "assimp_boxing_toes": (3069, 21, 5, 66),
    "cmu_01_01_forward_jumps": (2752, 31, 7, 96),
    "cmu_05_06_dance_cartwheel_start_iclone": (443, 100, 41, 303),
    "cmu_06_15_basketball_dribble_shoot_iclone": (273, 100, 41, 303),
    "cmu_09_01_run_daz": (149, 43, 14, 132),
    "cmu_10_01_soccer_kick_daz": (802, 43, 14, 132),
    "cmu_12_01_walk": (524, 31, 7, 96),
    "cmu_131_01_walk_start_stop_max": (994, 31, 7, 96),
    "cmu_14_19_laugh_idle_daz": (2727, 43, 14, 132),
    "cmu_16_01_jump_amc2bvh": (322, 31, 7, 96),
    "makehuman_zombie_walk_keyframed": (31, 75, 16, 228),
    "mocapbank_sit_down_stand_up": (455, 19, 5, 60),
}


def channel_values(motion, positions="standard"):
    from mocap_exaggerate.io.bvh import motion_channels

    return motion_channels(motion, positions=positions)


@pytest.mark.parametrize("path", all_clip_params())
def test_reads_counts_from_sources_table(path):
    motion, report = read_bvh(path)
    frames, joints, end_sites, channels = EXPECTED[path.stem]
    assert motion.num_frames == frames
    assert motion.skeleton.num_joints == joints
    assert int(np.isfinite(motion.skeleton.end_sites[:, 0]).sum()) == end_sites
    assert motion.skeleton.num_channels == channels
    assert np.all(np.isfinite(motion.local_rotations))
    assert np.allclose(np.linalg.norm(motion.local_rotations, axis=-1), 1.0)


@pytest.mark.parametrize("path", all_clip_params())
def test_round_trip_keeps_every_channel_and_the_layout(path):
    """Written in the input's own convention (``positions="input"``), a clip goes back out channel
    for channel; written in the standard one (the default), it reads back as the same motion."""
    motion, report = read_bvh(path)
    standard, standard_report = read_bvh(format_bvh(motion))
    assert standard_report.root_offset == "replace"
    np.testing.assert_allclose(standard.world_positions(), motion.world_positions(), atol=1e-5 * motion.skeleton.height())
    data = format_bvh(motion, positions="input")
    if report.root_offset == "replace":
        assert data == format_bvh(motion)
    again, _ = read_bvh(data)
    assert again.skeleton.positions == motion.skeleton.positions
    assert again.skeleton.names == motion.skeleton.names
    assert again.skeleton.channels == motion.skeleton.channels
    assert np.array_equal(again.skeleton.parents, motion.skeleton.parents)
    assert np.allclose(again.skeleton.offsets, motion.skeleton.offsets, atol=1e-6)
    assert np.allclose(again.skeleton.end_sites, motion.skeleton.end_sites, atol=1e-6, equal_nan=True)
    assert again.frame_time == pytest.approx(motion.frame_time, rel=1e-12)
    assert np.max(np.abs(channel_values(again, "input") - channel_values(motion, "input"))) <= 1e-4
    # Raw numbers in the source file agree too (the reader does not alter them).
    raw = np.array(path.read_bytes().split()[-(motion.num_frames * motion.skeleton.num_channels):], dtype=float)
    if "boxing" not in path.stem:  # that file has one row more than declared
        assert np.max(np.abs(channel_values(again, "input").ravel() - raw)) <= 1e-4
    # Written a second time, the bytes are the same.
    assert format_bvh(again, positions="input") == data


def test_written_numbers_are_fixed_point_with_lf_and_full_frame_time(sample_clip):
    motion, _ = read_bvh(sample_clip)
    text = format_bvh(motion).decode("ascii")
    assert "\r" not in text
    assert not re.search(r"\d[eE][-+]?\d", text)
    assert "-0.000000 " not in text
    assert "Frame Time: 0.00833333\n" in text


@pytest.mark.parametrize("path", shared_clip_params())
def test_world_positions_match_bvhio(path, tmp_path):
    """bvhio reads position channels as replacing the OFFSET; on a clip read as adding to it
    (iClone: the root alone has them) every joint is then the root's OFFSET higher than bvhio's."""
    motion, report = read_bvh(path)
    shift = motion.skeleton.offsets[0] if report.root_offset == "add" else np.zeros(3)
    if report.root_offset == "add":
        assert [j for j in range(motion.skeleton.num_joints) if motion.skeleton.has_position_channels(j)] == [0]
    frames = np.unique(np.linspace(0, motion.num_frames - 1, 12).astype(int))
    # bvhio parses every frame in Python (seconds on a long clip): hand it only the ones compared.
    sliced = tmp_path / path.name
    sliced.write_bytes(_with_frames(path.read_bytes(), frames))
    root = bvhio.readAsHierarchy(str(sliced))
    layout = root.layout()
    names = [joint.Name for joint, _, _ in layout]
    assert names == list(motion.skeleton.names)
    ours = motion.world_positions()
    tolerance = 1e-4 * motion.skeleton.height()
    for k, f in enumerate(frames):
        root.loadPose(k)
        theirs = np.array([list(joint.PositionWorld) for joint, _, _ in layout])
        assert np.max(np.abs(ours[f] - shift - theirs)) < tolerance, f"frame {f}"


def _with_frames(data: bytes, frames: np.ndarray) -> bytes:
    """The same BVH file with only the chosen motion lines."""
    head, _, body = data.partition(b"MOTION")
    lines = [line for line in body.splitlines()[1:] if line.strip()]
    frame_time = next(line for line in lines if line.strip().lower().startswith(b"frame time"))
    rows = lines[lines.index(frame_time) + 1 :]
    chosen = b"\n".join(rows[int(f)] for f in frames)
    return head + b"MOTION\nFrames: %d\n" % len(frames) + frame_time.strip() + b"\n" + chosen + b"\n"


def test_boxing_extra_row_is_a_warning_and_the_declared_count_is_kept():
    motion, report = read_bvh(shared("assimp_boxing_toes.bvh"))
    assert motion.num_frames == 3069
    assert report.data_lines == 3070
    assert any("3070" in w for w in report.warnings)


def test_fps_override_for_wrong_header():
    motion, report = read_bvh(shared("cmu_16_01_jump_amc2bvh.bvh"), fps=120)
    assert motion.frame_time == pytest.approx(1 / 120)
    assert report.header_fps == pytest.approx(30, rel=1e-4)
    assert any("120" in w for w in report.warnings)


def test_layout_variants_read():
    # "{" on the name line, a name with spaces, a leaf without End Site, position channels on a
    # non-root joint, scientific notation, CRLF, tabs, TAB after Frames:, ".1" frame time.
    text = (
        b"HIERARCHY\r\nROOT Bip01 Pelvis {\r\n\tOFFSET 0 0 0\r\n"
        b"\tCHANNELS 3 Xposition Yposition Zposition\r\n"
        b"\tJOINT Arm\n\t{\n\t\tOFFSET 1e0 0 -0.00000\n"
        b"\t\tCHANNELS 6 Yrotation Xposition Zrotation Yposition Xrotation Zposition\n\t}\n"
        b"}\r\nMOTION\r\nFrames:\t1\r\nFrame Time: .1\r\n"
        b"1 2 3 90 4 0 5 0 6\r\n"
    )
    motion, _ = read_bvh(text)
    assert motion.skeleton.names == ("Bip01 Pelvis", "Arm")
    assert motion.skeleton.rotation_order(1) == "YZX"
    assert motion.frame_time == pytest.approx(0.1)
    assert np.allclose(motion.local_positions[0, 1], [4, 5, 6])
    world = motion.world_positions()
    assert np.allclose(world[0, 1], [1 + 4, 2 + 5, 3 + 6])
    assert format_bvh(read_bvh(format_bvh(motion))[0]) == format_bvh(motion)


def test_one_frame_is_valid():
    motion, _ = read_bvh(make_bvh(SIMPLE, "Frames: 1\nFrame Time: 0.1\n1 2 3 10 20 30 5 6 7\n"))
    assert motion.num_frames == 1
    assert np.allclose(motion.world_positions()[0, 0], [1, 2, 3])


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_malformed_input_names_file_line_and_problem(name):
    data, line, words = MALFORMED[name]
    with pytest.raises(InputError) as caught:
        read_bvh(data, name="bad.bvh")
    error = caught.value
    message = str(error)
    assert message.startswith("bad.bvh:"), message
    assert "\n" not in message
    assert error.line == line, message
    assert words.lower() in message.lower(), message


def test_save_is_atomic_and_refuses_to_overwrite(tmp_path, sample_clip):
    motion, _ = read_bvh(sample_clip)
    target = tmp_path / "out.bvh"
    save_bvh(motion, target, overwrite=False)
    before = target.read_bytes()
    with pytest.raises(OutputExistsError, match="out.bvh exists"):
        save_bvh(motion, target, overwrite=False)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bvh"]


def test_writer_refuses_nan(sample_clip):
    motion, _ = read_bvh(sample_clip)
    positions = motion.local_positions.copy()
    positions[3, 0, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        format_bvh(motion.replace(local_positions=positions))
    # Infinities too, and two that cancel in a sum; huge finite numbers whose sum overflows are finite.
    rotations = motion.local_rotations.copy()
    rotations[2, 1, 0], rotations[5, 2, 3] = np.inf, -np.inf
    with pytest.raises(ValueError, match="infinite"):
        format_bvh(motion.replace(local_rotations=rotations))
    from mocap_exaggerate.io.bvh import _finite

    positions[3, 0, 1] = positions[4, 0, 1] = 1.7e308
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (the sum's overflow is not the user's business)
        assert _finite(positions) and not _finite(rotations)


@pytest.mark.parametrize("decimals", [0, 1, 4, 6, 9])
@pytest.mark.parametrize("scale", [1e-4, 1.0, 300.0, 5e8])
@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_fast_number_formatting_equals_printf(decimals, scale, compiled):
    from mocap_exaggerate.io import bvh

    if compiled and bvh._compiled is None:
        pytest.skip("the compiled formatter was not built (no C compiler at install); the NumPy one is tested")
    rng = np.random.default_rng(int(scale * 10) % 1000 + decimals)
    values = rng.normal(scale=scale, size=(40, 7))
    values[0] = [0.0, -0.0, -1e-12, 9.99999996, -99.99999996, 123456.5, 1e-3]
    values[1] = [0.5e-6, 1.5e-6, 2.5e-6, -0.5e-6, 0.5, 2.5, -3.5]  # halves: to even, as np.round
    expected_row = " ".join([f"%.{decimals}f"] * 7) + "\n"
    expected = (expected_row * 40) % tuple((np.round(values, decimals) + 0.0).ravel().tolist())
    assert bvh.format_fixed(values, decimals, compiled=compiled) == expected.encode()


def test_compiled_formatter_is_built_where_ci_runs():
    """.ci/run installs on a machine with a C compiler: the compiled formatter must be there (else the
    NumPy fallback would pass every test while the writer ran 6x slower)."""
    import shutil

    from mocap_exaggerate.io import bvh

    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler here: the install uses the NumPy formatter")
    from mocap_exaggerate.core import native

    if not native.ENABLED:
        pytest.skip(f"{native.NUMPY_ONLY} is set: the NumPy code runs")
    assert bvh._compiled is not None, "io/_formatting.c was not built: pip install -e . (setup.py builds it)"


def test_the_compiled_formatter_refuses_what_it_cannot_write():
    """Its buffer holds numbers under 1e9 in a C-contiguous native float64 array; anything else is a ValueError,
    never a write past its end (1e17 aborted the process before)."""
    from mocap_exaggerate.io import bvh

    if bvh._compiled is None:
        pytest.skip("the compiled formatter was not built")
    for values, rows, cols in [(np.full(64, 1e17), 8, 8), (np.full(2, np.nan), 1, 2), (b"", 2**61, 8),
                               (np.zeros(8, np.int64), 1, 8), (np.zeros(8, np.float32), 1, 8), (np.zeros(4), 1, 8)]:
        with pytest.raises((ValueError, BufferError)):
            bvh._compiled.format_fixed(values, rows, cols, 6)
    assert bvh.format_fixed(np.array([[1e9, 2.5e10, -0.5]])) == b"1000000000.000000 25000000000.000000 -0.500000\n"
    # Just under 1e9, rounding up to ten digits: every number one byte longer than nine digits allow.
    edge = np.full((2000, 50), -999999999.9999996)
    assert bvh.format_fixed(edge) == ((" ".join(["-1000000000.000000"] * 50) + "\n") * 2000).encode()


def _both_readers(block: bytes, channels: int, declared: int):
    """``_parse_motion`` on ``block`` by io/_formatting.c and by NumPy: (values or error, lines, warnings) each."""
    from mocap_exaggerate.io import bvh

    results = []
    for compiled in (True, False):
        report = bvh.BVHReport(source="x")
        try:
            values = bvh._parse_motion(block, channels, declared, first_line=5, label="x", report=report,
                                       compiled=compiled).tobytes()
        except InputError as error:
            values = str(error)
        results.append((values, report.data_lines, report.warnings))
    return results


def test_the_compiled_reader_gives_numpys_values_for_every_way_of_writing_a_number():
    """Every number is the double nearest its text, as NumPy's strtod reads it: short decimals (one IEEE
    quotient), long mantissas, large and tiny powers of ten, signed zeros, subnormals, the edge of the
    range; and every fault (a word, a hex number, a value past 1e9, a short line) is named as before."""
    from mocap_exaggerate.io import bvh

    if bvh._compiled is None:
        pytest.skip("io/_formatting.c was not built")
    rng = np.random.default_rng(31)
    words = ["0", "-0", "+0.000", "-0.0e5", ".5", "5.", "-.25E-3", "1e-22", "1e-23", "9007199254740993e-10",
             "12345678901234567890123e-20", "1e8", "100000000.000000000000001",
             "0.1000000000000000055511151231257827", "1e-320", "-4.9e-324",
             "999999999.99999999", "1000000000", "-1e9", "00012.50", "1.7976931348623157e-300", "3.14159265358979323846",
             "123456.789012", "-0.000001", "2.2250738585072014e-308", "1E+08", "7e-0", "0e999999"]
    words += [f"{v:.{d}f}" for v, d in zip(rng.uniform(-2e3, 2e3, 400), rng.integers(0, 12, 400))]
    words += [f"{v:.{d}e}" for v, d in zip(rng.uniform(-1e9, 1e9, 200) * 10.0 ** rng.integers(-30, 0, 200),
                                            rng.integers(0, 20, 200))]
    words += [repr(float(v)) for v in rng.normal(0, 100, 200)]
    rng.shuffle(words)
    rows = [words[k:k + 6] for k in range(0, len(words) - len(words) % 6, 6)]
    for end in ("\n", "\r\n"):
        block = ("\t".join(rows[0]) + end + end.join(" \x0b ".join(row) + "  " for row in rows[1:])).encode()
        ours, theirs = _both_readers(block, 6, len(rows))
        assert ours == theirs and isinstance(ours[0], bytes)
    # More lines than declared (a warning), blank lines between, no LF at the end:
    block = b"\n\n1 2 3\n   \n4 5 6\n7 8 9"
    assert _both_readers(block, 3, 2)[0] == _both_readers(block, 3, 2)[1]
    assert _both_readers(block, 3, 2)[0][2] and _both_readers(block, 3, 2)[0][1] == 3
    for bad in (b"1 2 x\n4 5 6\n", b"1 2 0x10\n4 5 6\n", b"1 2 nan\n4 5 6\n", b"1 2 inf\n4 5 6\n", b"1 2 1e10\n4 5 6\n",
                b"1 2 3\n4 5\n", b"1 2 3 4\n4 5 6\n", b"1 2 3\n", b"1 2 3e\n4 5 6\n", b"1 2 .\n4 5 6\n",
                b"1 2 3-\n4 5 6\n", b"1 2 1e99999\n4 5 6\n", b"1 2 1_0\n4 5 6\n", b"1 2 3\x00\n4 5 6\n"):
        ours, theirs = _both_readers(bad, 3, 2)
        assert ours == theirs and isinstance(ours[0], str), bad
    # A header declaring far more than the block holds: named, nothing the size of its claim allocated.
    ours, theirs = _both_readers(b"1 2 3\n", 3, 400_000)
    assert ours == theirs and "only 1 complete motion lines" in ours[0]
    with pytest.raises(ValueError, match="declared"):
        bvh._compiled.parse_motion(b"1 2 3\n", np.empty(2), 3, 1, 1e9)
    with pytest.raises(TypeError):  # only bytes: its closing NUL ends the last number
        bvh._compiled.parse_motion(bytearray(b"1 2 3\n"), np.empty(3), 3, 1, 1e9)
    for wrong in (np.zeros(6, np.float32), np.zeros(3, np.int64), np.zeros(6)[::2]):  # (a review wrote doubles in floats)
        with pytest.raises((ValueError, BufferError), match="float64|contiguous"):
            bvh._compiled.parse_motion(b"1 2 3\n", wrong, 3, 1, 1e9)
    # A number of thousands of digits (no exporter writes one) is left to the NumPy reader, with the same value:
    huge = b"1" + b"0" * 5000 + b"e-5000 2 3\n4 5 6\n"
    ours, theirs = _both_readers(huge, 3, 2)
    assert ours == theirs and isinstance(ours[0], bytes)


@pytest.mark.parametrize("path", all_clip_params())
def test_both_readers_read_every_clip_alike(path):
    from mocap_exaggerate.io import bvh

    if bvh._compiled is None:
        pytest.skip("io/_formatting.c was not built")
    data = path.read_bytes()
    start = data.index(b"Frame Time:")
    block = data[data.index(b"\n", start) + 1:]
    declared = int(re.search(rb"Frames:\s*(\d+)", data).group(1))
    channels = sum(int(n) for n in re.findall(rb"CHANNELS\s+(\d+)", data[:start]))
    ours, theirs = _both_readers(block, channels, declared)
    assert ours == theirs and isinstance(ours[0], bytes)


def test_both_formatters_write_a_whole_clip_alike(sample_clip):
    from mocap_exaggerate.io import bvh

    if bvh._compiled is None:
        pytest.skip("the compiled formatter was not built")
    motion, _ = read_bvh(sample_clip)
    values = bvh.motion_channels(motion)
    assert bvh.format_fixed(values) == bvh.format_fixed(values, compiled=False)


@pytest.mark.parametrize("path", all_clip_params())
def test_motion_lines_read_where_they_lie_are_the_tables_bytes(path):
    """The writer's compiled path takes each channel from the block's positions and Euler angles
    (`format_columns`); the NumPy path makes a table of channels and formats it: the same bytes on every
    clip, written back and exaggerated (95 joints, six channels each), in blocks that cut the clip."""
    from mocap_exaggerate.io import bvh
    from mocap_exaggerate.pipeline import run

    if bvh._compiled is None:
        pytest.skip("the compiled formatter was not built")
    motion, _ = read_bvh(path)
    for clip in (motion, run(motion).motion):
        for positions in ("standard", "input"):
            ours = b"".join(bvh._motion_lines(clip, 97, positions))
            assert ours == b"".join(bvh._motion_lines(clip, 97, positions, compiled=False))


def test_motion_lines_past_the_compiled_formatters_reach_are_written_as_python_writes_them(sample_clip):
    """A position of 1e9 or more (the compiled loop's limit) in one block: that block is formatted by
    Python, as a table's would be; the others as before."""
    from mocap_exaggerate.io import bvh

    motion, _ = read_bvh(sample_clip)
    far = motion.local_positions.copy()
    far[120, 0, 1] = 2.5e10
    moved = motion.replace(local_positions=far)
    ours = b"".join(bvh._motion_lines(moved, 100))
    assert ours == b"".join(bvh._motion_lines(moved, 100, compiled=False))
    assert b" 25000000000.000000 " in ours


def test_the_compiled_column_formatter_refuses_what_it_cannot_read():
    from mocap_exaggerate.io import bvh

    if bvh._compiled is None:
        pytest.skip("the compiled formatter was not built")
    table = np.zeros((4, 6))
    picks = np.array([0, -1, 5], dtype=np.int64)
    assert bvh._compiled.format_columns(table, table[:, :3].copy(), picks, 4, 6, 3, 6) == b"0.000000 0.000000 " \
        b"0.000000\n" * 4
    for args in [(table, table, np.array([6]), 4, 6, 6, 6),  # a pick past its table
                 (table, table, np.array([-7]), 4, 6, 6, 6),
                 (table, table, np.array([], dtype=np.int64), 4, 6, 6, 6),  # no columns
                 (table, table, picks.astype(np.int32), 4, 6, 6, 6),  # not int64
                 (table, table[:, :3], picks, 4, 6, 3, 6),  # not contiguous
                 (table, table, picks, 5, 6, 6, 6),  # more rows than the tables hold
                 (table, table, picks, 2**62, 6, 6, 6),
                 (table.astype(np.float32), table, picks, 4, 6, 6, 6),
                 (np.full((4, 6), np.nan), table, picks, 4, 6, 6, 6),
                 (table, table, picks, 4, 6, 6, 10)]:
        with pytest.raises((ValueError, BufferError)):
            bvh._compiled.format_columns(*args)


def test_a_file_cut_inside_the_hierarchy_says_so(tmp_path):
    """A clip cut in the middle of a word of its hierarchy named the word and no more (a new user's trial:
    `unexpected 'CHA' in joint 'LThumb'`): it says the file ends there. A fault elsewhere is named as it was."""
    data = (SAMPLE_DIR / "cmu_09_01_run_daz.bvh").read_bytes()
    cut = data[: data.index(b"CHANNELS", 5000) + 3]
    with pytest.raises(InputError, match=r"unexpected 'CHA' in joint .*; the file ends on this line, inside the "
                                         r"hierarchy \(truncated\?\)") as caught:
        read_bvh(cut)
    assert caught.value.line == cut.count(b"\n") + 1
    with pytest.raises(InputError, match=r"file ends where '}'( closing joint .*)? was expected$"):
        read_bvh(data[: data.index(b"}", 3000) - 2])
    broken = data.replace(b"CHANNELS", b"CHANELS", 1)
    with pytest.raises(InputError, match=r"CHANELS") as caught:
        read_bvh(broken)
    assert "truncated" not in str(caught.value)


@pytest.mark.parametrize("name, text, error", [
    ("numbers on one OFFSET line", "HIERARCHY\nROOT r\n{\nOFFSET " + "1 " * 2_000_000 + "\n}\n", ":4: unexpected '1'"),
    ("channel names on one line", "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation"
     + " Xrotation" * 1_000_000 + "\n}\n", ":5: CHANNELS says 3 but lists more than 67"),
    ("End Sites on one joint", "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\n" + "End Site\n{\nOFFSET 0 1 0\n}\n" * 200_000
     + "}\nMOTION\nFrames: 1\nFrame Time: 0.1\n\n", ":9: joint 'r' has a second End Site"),
    ("words in a joint's name", "HIERARCHY\nROOT " + "r " * 1_000_000 + "{\n", ":2: more than 64 words"),
])
def test_a_flood_in_the_hierarchy_is_refused_at_its_first_wrong_word_in_little_memory(name, text, error):
    """The hierarchy's words are read one at a time: split into lists whole, 50 million numbers on
    an OFFSET line took 60 times the file (6.2 GB for 100 MB) before the refusal."""
    import tracemalloc

    data = text.encode()
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as caught:
            read_bvh(data, name="flood.bvh")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert str(caught.value).startswith("flood.bvh" + error), str(caught.value)[:200]
    assert peak < 3 * len(data), (name, peak / len(data))
