"""The core: what a clip is and how it moves, with nothing of the method in it.

`skeleton` (joints, offsets, channels), `motion` (a skeleton with its frames),
`rotations` (quaternions and Euler orders), `kinematics` (forward kinematics),
`timing` (durations, Gaussian averages and the easing filters along time),
`errors` (the three errors users see, and the checks that raise them).
"""
