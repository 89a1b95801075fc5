"""The stages of the pipeline, one module each, in docs/ALGORITHM.md's order: scalespace (1), detector
(2, with filters), descriptors (3), mahalanobis (4), matcher (4), constraints (5), estimator (6),
decision (7-8). :mod:`scalematch.pipeline` calls them.
"""
