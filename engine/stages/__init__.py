"""The registration stages (thesis chapter 4), one module each; :mod:`engine.pipeline` runs them.

    perception   stage 0, learned part: person mask, 2D keypoints, facing (beyond the thesis)
    foreground   stage 0: body regions and edges (4.1)
    calibration  stage 1: the camera from the first frame (4.2)
    alignment    stage 2: approximate temporal correspondence by DP (4.5)
    candidates   stage 3: posture candidates per frame by belief propagation (4.6)
    selection    stage 4: segment boundaries, candidate selection, refined C (4.7)
    assessment   how far to trust the selection: fit, uncertainty, misfit (beyond the thesis)
    repetitions  repetitions of a motion in one video (beyond the thesis)
"""
