"""The skeleton: joint names, a parents vector, rest offsets and the BVH channel layout."""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass, field, replace

import numpy as np

from .errors import check_choice
from .kinematics import forward_kinematics, parent_rotations, rest_positions
from .rotations import quat_rotate

__all__ = ["Skeleton", "POSITION_CHANNELS", "ROTATION_CHANNELS"]

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
#: What a joint's position channels do to its OFFSET.
POSITION_MODES = ("replace", "add")


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy as arrays.

    Attributes
    ----------
    names : tuple of str, length J
    parents : (J,) int64, -1 for the root; ``parents[j] < j`` always
    offsets : (J, 3) float64, rest offset of each joint from its parent
    channels : tuple of J tuples of BVH channel names as read, e.g.
        ``("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")``
    end_sites : (J, 3) float64, End Site offset of each joint, NaN where a joint has none
    positions : ``replace`` when a joint's position channels replace its OFFSET (bvhio,
        Blender, most readers); ``add`` when they add to it (Reallusion/iClone, MakeHuman)
    up : the axis (0, 1, 2) the body stands along when it was given; None: `up_axis` works it out
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    end_sites: np.ndarray
    positions: str = "replace"
    up: int | None = None
    _index: dict[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        parents = np.asarray(self.parents, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        end_sites = np.asarray(self.end_sites, dtype=np.float64)
        n = len(self.names)
        if parents.shape != (n,) or offsets.shape != (n, 3) or end_sites.shape != (n, 3):
            raise ValueError(
                f"skeleton arrays disagree: {n} names, parents {parents.shape}, "
                f"offsets {offsets.shape}, end_sites {end_sites.shape}"
            )
        if len(self.channels) != n:
            raise ValueError(f"skeleton has {n} joints but {len(self.channels)} channel lists")
        check_choice("positions", self.positions, POSITION_MODES, error=ValueError)
        if self.up not in (None, 0, 1, 2):
            raise ValueError(f"up must be None, 0, 1 or 2, got {self.up!r}")
        if n == 0 or parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, n)):
            raise ValueError("parents must start with the root (-1) and list every parent before its children")
        for array in (parents, offsets, end_sites):
            array.setflags(write=False)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "end_sites", end_sites)
        object.__setattr__(self, "channels", tuple(tuple(c) for c in self.channels))
        object.__setattr__(self, "_index", {name: j for j, name in enumerate(self.names)})

    # ------------------------------------------------------------------ topology
    @property
    def num_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of the joint called ``name``; ``KeyError`` naming it if absent."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"no joint named {name!r}") from None

    def children(self, joint: int) -> np.ndarray:
        """Indices of the direct children of ``joint``."""
        return np.flatnonzero(self.parents == joint)

    def subtree_sizes(self) -> np.ndarray:
        """(J,) how many joints each joint's subtree holds, itself included (parents come first)."""
        sizes = np.ones(self.num_joints, dtype=np.int64)
        for j in range(self.num_joints - 1, 0, -1):
            sizes[self.parents[j]] += sizes[j]
        return sizes

    def descendants(self, joint: int) -> np.ndarray:
        """Indices of ``joint`` and every joint below it, in order.

        A level of the subtree a step, over all joints at once (a joint by joint loop, called once for each
        joint of a 10,000-joint star, took 6.5 s)."""
        inside = np.zeros(self.num_joints, bool)
        inside[joint] = True
        later = np.arange(joint + 1, self.num_joints)
        parents = self.parents[later]
        count = 1
        while True:
            inside[later] = inside[parents]
            inside[joint] = True
            now = int(np.count_nonzero(inside))
            if now == count:
                return np.flatnonzero(inside)
            count = now

    def ancestors(self, joint: int) -> list[int]:
        """``joint`` and every joint above it, up to the root, in that order."""
        out = []
        while joint >= 0:
            out.append(int(joint))
            joint = int(self.parents[joint])
        return out

    def depth(self) -> np.ndarray:
        """Number of links from the root to each joint, ``(J,)``."""
        depth = np.zeros(self.num_joints, np.int64)
        for j in range(1, self.num_joints):
            depth[j] = depth[self.parents[j]] + 1
        return depth

    def match(self, pattern: str) -> np.ndarray:
        """Indices of joints whose name matches a shell pattern (``Left*``), case-sensitive."""
        return np.array(
            [j for j, name in enumerate(self.names) if fnmatch.fnmatchcase(name, pattern)],
            dtype=np.int64,
        )

    # ------------------------------------------------------------------ channels
    def rotation_order(self, joint: int) -> str:
        """Intrinsic rotation order of ``joint`` as three letters, e.g. ``"ZXY"``.

        Axes the joint has no channel for are appended (their angle is zero),
        so every joint has a full order.
        """
        axes = "".join(c[0].upper() for c in self.channels[joint] if c in ROTATION_CHANNELS)
        return axes + "".join(a for a in "ZXY" if a not in axes)

    def has_position_channels(self, joint: int) -> bool:
        return any(c in POSITION_CHANNELS for c in self.channels[joint])

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    def with_full_channels(self) -> Skeleton:
        """The same skeleton with position and rotation channels on every joint.

        Rotation orders are kept joint by joint, so channel curves stay
        comparable with the input's.
        """
        channels = tuple(
            POSITION_CHANNELS + tuple(f"{a}rotation" for a in self.rotation_order(j))
            for j in range(self.num_joints)
        )
        return Skeleton(self.names, self.parents, self.offsets, channels, self.end_sites, self.positions, self.up)

    # ------------------------------------------------------------------ geometry
    def rest_positions(self) -> np.ndarray:
        """World positions of the joints in the rest pose (offsets only), ``(J, 3)``."""
        return rest_positions(self.parents, self.offsets)

    def posed(self, pose: np.ndarray) -> tuple[Skeleton, np.ndarray]:
        """This skeleton with ``pose`` for its rest pose, and that pose's world rotations ``(J, 4)``.

        pose : (J, 4) local rotations; each offset (and End Site) is turned into the pose,
            so the new rest positions are this skeleton's posed by them (see `Motion.with_rest`)
        """
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (self.num_joints, 4):
            raise ValueError(f"pose must be ({self.num_joints}, 4), got {pose.shape}")
        world = forward_kinematics(self.parents, pose[None], np.zeros((1, self.num_joints, 3)))[0][0]
        above = parent_rotations(self.parents, world)
        end_sites = quat_rotate(world, np.nan_to_num(self.end_sites))
        end_sites[np.isnan(self.end_sites)] = np.nan
        return replace(self, offsets=quat_rotate(above, self.offsets), end_sites=end_sites), world

    def link_lengths(self) -> np.ndarray:
        """Rest length of the link from each joint's parent to it, ``(J,)``; 0 for the root."""
        lengths = np.linalg.norm(self.offsets, axis=1)
        lengths[0] = 0.0
        return lengths

    def up_axis(self) -> int:
        """Index (0, 1, 2) of the axis the body stands along in the rest pose.

        Legs and spine together are longer than the arms, so the axis that
        carries most of the summed link length is taken as up (unless it was given: ``up``).
        """
        if self.up is not None:
            return self.up
        return int(np.argmax(np.abs(self.offsets[1:]).sum(axis=0)))

    def height(self) -> float:
        """Extent of the rest pose along the up axis: the natural length scale."""
        rest = self.rest_positions()
        ends = rest[np.isfinite(self.end_sites[:, 0])] + self.end_sites[np.isfinite(self.end_sites[:, 0])]
        points = np.concatenate([rest, ends])
        axis = self.up_axis()
        extent = float(np.ptp(points[:, axis]))
        return extent if extent > 0 else float(np.ptp(points, axis=0).max() or 1.0)
