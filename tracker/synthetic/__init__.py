"""The rendered-data generator: recordings with ground truth made to test the tracking method (docs/suite.md).

It exists to test :mod:`tracker.tracking` and is never imported by it (tests/test_layers.py checks that).

render.py             the renderer: the ray caster's hits (:mod:`tracker.raycast`) shaded and composited, motion blur
texture.py            clothing textures painted in the components' frames
props.py              opaque boxes (tables) in a rendered scene
room.py               an empty furnished room ray-cast from each camera as a render's backdrop
face.py               a face and hair painted on the head
clips.py              motion clips: BVH retargeted, procedural, athletic, seated
actor.py              rendered bodies unlike the model (capsules, or the model's parts, of perturbed sizes)
synth.py              rendered recordings with ground truth (``tracker synth``) and the rigs of ``calib/``
suite.py              the hard suite of renders and its scores (``tracker suite``)
keypoint_accuracy.py  the keypoint detector scored against a render's truth
detector_baseline.py  the detector's landmarks triangulated frame by frame: the baseline the tracker must beat
"""
