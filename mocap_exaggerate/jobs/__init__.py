"""Running the job: one clip's whole output set (`job`), what is written beside the motion
(`outputs`), and many clips at once (`batch`)."""
