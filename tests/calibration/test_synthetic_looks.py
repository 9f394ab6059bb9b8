"""The simulated cameras and scenes draw on their GreyLook's ground and develop through it."""

from __future__ import annotations

import numpy as np

from labauto.synthetic.camera import DECK_CAMERA_LOOK, CameraModel, SceneCamera
from labauto.synthetic.grey_look import GreyLook
from labauto.synthetic.head_camera import HEAD_CAMERA_LOOK, SimulatedHeadCamera, deck_to_image
from labauto.synthetic.marker_sequences import SequenceSpec

K = np.array([[1400.0, 0.0, 640.0], [0.0, 1400.0, 512.0], [0.0, 0.0, 1.0]])


def test_canvas_is_the_ground_and_develop_rounds_to_uint8() -> None:
    look = GreyLook(ground=100.4, ink=20.0)
    canvas = look.canvas((5, 3))
    assert canvas.shape == (3, 5) and canvas.dtype == np.float64 and (canvas == 100.4).all()
    developed = look.develop(canvas, None)  # no noise: no rng needed
    assert developed.dtype == np.uint8 and (developed == 100).all()


def test_an_empty_deck_is_the_looks_ground() -> None:
    model = CameraModel.looking_down(K, np.zeros(5), (80.0, 70.0, 140.0), (64, 48))
    flat = GreyLook(ground=140.0, ink=25.0)
    assert (SceneCamera(model, look=flat).capture() == 140).all()
    noisy = SceneCamera(model).capture()  # the default look: a 150 deck with noise
    assert DECK_CAMERA_LOOK.ground == 150.0 and abs(float(noisy.mean()) - 150.0) < 1.0


def test_the_head_camera_draws_the_marker_in_the_looks_ink() -> None:
    look = GreyLook(ground=200.0, ink=10.0)
    camera = SimulatedHeadCamera(lambda: (32.0, 24.0), deck_to_image(np.eye(3)), 3, 4.0,
                                 size=(64, 48), look=look)  # fmt: skip
    image = camera.capture()
    assert image[24, 32] == 10 and image[0, 0] == 200 and camera.captures == 1
    assert HEAD_CAMERA_LOOK.blur_sigma == 0.6


def test_a_sequence_look_is_its_paper_ink_and_noise() -> None:
    spec = SequenceSpec(paper=200.0, ink=30.0, noise_sigma=1.5)
    assert spec.look == GreyLook(200.0, 30.0, blur_sigma=0.0, noise_sigma=1.5)
