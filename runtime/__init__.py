"""spacepose: stereo 6-DoF pose of a non-cooperative spacecraft.

The flight runtime (this package) needs only numpy, onnxruntime and OpenCV; it never imports torch.
Training-side parts live in ``spacepose.models``, ``spacepose.export`` and ``spacepose.tools``
and need the ``[train]`` extra.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
