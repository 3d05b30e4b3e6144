"""Issue 25, part 5: limbs kept out of the body, knees and elbows bending the captured way."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocap_exaggerate import load_bvh, load_preset
from mocap_exaggerate.analysis.body import body_capsules, inside_body, limb_parts, penetrations, segment_closest
from mocap_exaggerate.analysis.limbs import find_limbs
from mocap_exaggerate.analysis.quality import motion_quality
from mocap_exaggerate.pipeline import run
from mocap_exaggerate.stages.collide import _back_to, _links_no_longer, _share_within, eased_push

from .helpers import SAMPLE_DIR, shared


def test_segment_closest_known_answers():
    p0, p1 = np.array([[0.0, 0, 0], [0, 0, 0], [0, 0, 0]]), np.array([[2.0, 0, 0], [2, 0, 0], [0, 0, 0]])
    q0 = np.array([[1.0, 1, -1], [3.0, 1, 0], [0, 3, 0]])
    q1 = np.array([[1.0, 1, 1], [4.0, 1, 0], [0, 3, 0]])
    s, t, gap = segment_closest(p0, p1, q0, q1)
    # Crossing segments 1 apart; parallel-ish ones ending past each other; a point to a point.
    np.testing.assert_allclose(s, [0.5, 1.0, 0.0])
    np.testing.assert_allclose(t, [0.5, 0.0, 0.0])
    np.testing.assert_allclose(gap, [[0, -1, 0], [-1, -1, 0], [0, -3, 0]], atol=1e-12)


def test_a_hand_put_through_the_chest_is_inside_and_its_way_out_is_away_from_the_spine():
    motion = load_bvh(SAMPLE_DIR / "mocapbank_sit_down_stand_up.bvh")
    limbs = find_limbs(motion.skeleton)
    pose = np.repeat(motion.world_positions()[:1], 3, axis=0)
    assert not inside_body(limbs, pose).any()  # standing, arms down: nothing inside
    spine = limbs["spine"]
    chest = 0.5 * (pose[1, spine.joints[1]] + pose[1, spine.joints[2]])
    arm = limbs["right_arm"]
    pose[1, arm.joints[2]] = chest  # the wrist in the middle of the chest
    inside = inside_body(limbs, pose)
    assert inside.tolist() == [False, True, False]
    depth, away, along, trunk = penetrations(pose, body_capsules(limbs, pose), limb_parts(limbs))["right_forearm"]
    assert depth[1] > 0 and trunk[1] and along[1] == pytest.approx(1.0)
    assert np.linalg.norm(away[1]) == pytest.approx(1.0)


def test_depths_measured_only_near_a_capsule_are_every_depth_inside():
    """`penetrations` measures a part against a capsule only on frames where their bounding boxes are within
    the radius: wherever a part is inside, depth, way out, place along and trunk are those of the deepest
    capsule, measured on every frame (the two are compared on a clip shaken to put limbs through the body)."""
    motion = load_bvh(SAMPLE_DIR / "mocapbank_sit_down_stand_up.bvh")
    limbs = find_limbs(motion.skeleton)
    pose = motion.world_positions()
    shaken = pose + np.random.default_rng(5).normal(scale=0.15 * motion.skeleton.height(), size=pose.shape)
    capsules, parts = body_capsules(limbs, pose), limb_parts(limbs)
    found = penetrations(shaken, capsules, parts)
    inside = 0
    for part in parts:
        deepest = np.full(len(pose), -np.inf)
        along = np.zeros(len(pose))
        for capsule in (c for c in capsules if c.name in part.avoid):
            q0, q1 = capsule.ends(shaken)
            s, _, gap = segment_closest(shaken[:, part.a], shaken[:, part.b], q0, q1)
            depth = capsule.radius - np.linalg.norm(gap, axis=-1)
            along = np.where(depth > deepest, s, along)
            deepest = np.maximum(deepest, depth)
        depth, _, measured_along, _ = found[part.name]
        assert np.array_equal(depth > 0, deepest > 0), part.name
        assert np.array_equal(depth[deepest > 0], deepest[deepest > 0]), part.name
        assert np.array_equal(measured_along[deepest > 0], along[deepest > 0]), part.name
        inside += int(np.sum(deepest > 0))
    assert inside > 100  # (the shaking put parts inside on many frames)


def test_an_eased_push_covers_every_frame_and_grows_and_fades():
    push = np.zeros((40, 3))
    push[18:22, 0] = 1.0
    eased = eased_push(push, 6)
    assert np.all(eased[18:22, 0] >= 1.0 - 1e-12)  # never short of a frame's own push
    assert eased[5, 0] == 0.0 and eased[35, 0] == 0.0  # and nothing far from it
    assert np.abs(np.diff(eased[:, 0])).max() < 0.35  # no step of the whole push in a frame
    # Near the clip's ends the push fades, but never below a frame's own (a run's forearm six frames in
    # stayed in the chest).
    early = np.zeros((40, 3))
    early[2:4, 1] = 1.0
    assert np.all(eased_push(early, 6)[2:4, 1] >= 1.0 - 1e-12)
    assert eased_push(early, 6)[0, 1] < 1.0


@pytest.mark.parametrize("clip", ["assimp_boxing_toes.bvh", "cmu_14_19_laugh_idle_daz.bvh"])
def test_forearms_stay_out_of_the_body_where_the_capture_does(clip):
    # Before: the boxer at cartoon had forearms in the torso on 289 frames (0 captured), the laugh at looney 425 (27).
    motion = load_bvh(shared(clip))
    config = load_preset("cartoon")
    result = run(motion, config)
    quality = motion_quality(motion, result)
    pushed = result.constraints["body"]["pushed"]
    assert pushed.get("left_forearm", 0) + pushed.get("right_forearm", 0) > 20  # forearms went in and came out
    assert quality["inside"] <= quality["inside_captured"], quality["inside"]  # (the boxer's shin: 3 frames before)
    off = motion_quality(motion, run(motion, replace(config, contacts=replace(config.contacts, collide=False))))
    assert off["inside"] > quality["inside"] + 20  # the pass is what keeps them out


def test_the_body_pass_gives_the_same_bytes_whatever_the_hash_seed(tmp_path):
    # Its limbs were taken from a set of names, in an order each process draws anew: three processes gave
    # three different boxers at looney. Same input and settings, same bytes.
    import os
    import subprocess
    import sys

    clip = shared("assimp_boxing_toes.bvh")
    written = []
    for seed in ("1", "2"):
        out = tmp_path / seed
        done = subprocess.run([sys.executable, "-m", "mocap_exaggerate_cli.main", "exaggerate", str(clip), "-o", str(out),
                               "--preset", "looney", "--no-glb"], capture_output=True, text=True,
                              env={**os.environ, "PYTHONHASHSEED": seed})
        assert done.returncode == 0, done.stderr
        written.append((out / "assimp_boxing_toes.bvh").read_bytes())
    assert written[0] == written[1]


def test_a_knee_moved_for_a_held_foot_keeps_its_links_to_their_longest():
    hip, knee, foot = np.array([[0.0, 2.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.0, 0.0]])
    # Straight out sideways by 1: both links would grow to sqrt(2); the thigh may reach 1.2 (its longest).
    move = _links_no_longer(hip, knee, foot, np.array([[1.0, 0.0, 0.0]]), 1.2, 1.0)
    # Where the two balls meet, out to that side: x^2 + y^2 = 1, x^2 + (y - 2)^2 = 1.44 -> y = 0.89.
    assert np.allclose(knee + move, [[np.sqrt(1 - 0.89**2), 0.89, 0.0]], atol=1e-3)
    # On a bent knee, a move toward the hip-foot line shortens both links: it is left as it is.
    bent = np.array([[0.6, 1.0, 0.0]])
    inward = np.array([[-0.3, 0.0, 0.0]])
    assert np.array_equal(_links_no_longer(hip, bent, foot, inward, 1.0, 1.0), inward)
    # The same move outward lengthens both past their longest (the bent lengths, sqrt(1.36)): cut to them.
    out = bent + _links_no_longer(hip, bent, foot, -inward, 1.0, 1.0)
    assert np.linalg.norm(out - hip) == pytest.approx(np.sqrt(1.36), abs=1e-5)
    assert np.linalg.norm(out - foot) == pytest.approx(np.sqrt(1.36), abs=1e-5)


def test_the_body_moves_off_a_knelt_on_shin_at_most_back_to_the_capture():
    root = np.array([[0.0, 0.5, 0.0], [0.0, 0.5, 0.0], [0.0, 1.2, 0.0]])
    captured = np.array([[0.0, 1.0, 0.0]] * 3)
    up = np.array([[0.0, 0.3, 0.0], [0.0, 0.8, 0.0], [0.0, 0.3, 0.0]])
    shift = _back_to(root, captured, up, 0.1)
    # 0.3 of the 0.6 back (with the slack) is kept; 0.8 is cut to 0.6; a root already above goes nowhere.
    assert np.allclose(shift, [[0.0, 0.3, 0.0], [0.0, 0.6, 0.0], [0.0, 0.0, 0.0]])


def test_a_planted_leg_moves_the_body_no_further_than_it_reaches_straight():
    # Hip 1 above the foot, the leg 1.5 long when straight: a lift of 1 is cut to 0.5.
    offset = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    shift = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, -0.5, 0.0]])
    share = _share_within(offset, shift, np.array([1.5, 1.5, 1.5]))
    assert share[0] == pytest.approx(0.5)
    assert share[1] == pytest.approx(1.0)  # sqrt(1 + 1) = 1.41 < 1.5: all of it
    assert share[2] == pytest.approx(1.0)  # down: shorter
