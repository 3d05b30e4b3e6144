"""What rides on the skeleton: skins and their re-weighting onto the rubber skeleton
(`skinning`), the default body grown from a skeleton (`body`), and fitting a character made
for another rig (`binding`)."""
