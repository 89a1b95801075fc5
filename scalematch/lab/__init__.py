"""The lab: synthetic pairs with exact truth, the error measure, the OpenCV peers, the benchmark,
the repeatability and descriptor studies and the covariance estimation (``scalematch lab ...``).

It builds on the product (:mod:`scalematch`); the product never imports it.
"""
