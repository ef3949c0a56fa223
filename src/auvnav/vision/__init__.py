"""Vision: stereo features, loop-closure candidates from the navigation, verified 6-DOF loop closures.

- :mod:`~auvnav.vision.camera`: rectification, triangulation with covariance, image checks;
- :mod:`~auvnav.vision.features`: illumination correction, SIFT, descriptor matching;
- :mod:`~auvnav.vision.stereo`: stereo matching along epipolar lines, the per-pair feature cache;
- :mod:`~auvnav.vision.candidates`: footprints, overlap probability, the navigation drift model;
- :mod:`~auvnav.vision.registration`: RANSAC, weighted and robust 3-D registration, covariance;
- :mod:`~auvnav.vision.loops`: loop closures of a dive; :mod:`~auvnav.vision.loopfile`: ``loops.csv``;
- :mod:`~auvnav.vision.network`: the images and their loops as one pose graph, the priors of pairs far apart;
- :mod:`~auvnav.vision.stage`: the ``auvnav loops`` stage and its products in ``products/vision/``;
- :mod:`~auvnav.vision.evaluate`: loop closures against a simulated dive's truth.
"""
