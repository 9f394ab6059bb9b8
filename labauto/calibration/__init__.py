"""Calibration applications (the paper's section 4.2): boards, camera, deck, and their files.

* :mod:`labauto.calibration.boards_io`: printable boards (SVG, PDF, PNG) and board YAML;
* :mod:`labauto.calibration.camera`: ``labauto.calibrate_camera`` from images of a board;
* :mod:`labauto.calibration.deck`: ``labauto calibrate deck`` (head marker or board on the deck);
* :mod:`labauto.calibration.files`: OpenCV FileStorage YAML export.

The algorithms are pure functions in :mod:`labauto.vision` (``markers``, ``boards``,
``board_points``, ``calibration``, ``deck``); these modules read files, talk to devices and the
store, and turn failures into one-line :class:`~labauto.errors.CalibrationError` messages.
"""
