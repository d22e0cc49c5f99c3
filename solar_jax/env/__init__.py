"""The MJX locomotion task: one world's pure functions, and the padded multi-morphology batch."""
