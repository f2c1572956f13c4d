"""Heatmap detectors (PnLCalib-compatible networks). Import submodules explicitly; this package
does not import torch on import.

``pnlviz.detect`` is also the API's detect function: ``pnlviz.detect(image)`` calls
:func:`pnlviz.detect.image.detect_image` (the package and the function share the name, so the
package is made callable).
"""

import sys
import types


class _CallablePackage(types.ModuleType):
    def __call__(self, image, weights=None, *, threshold: float = 0.1) -> dict:
        from pnlviz.detect.image import detect_image

        return detect_image(image, weights, threshold=threshold)


sys.modules[__name__].__class__ = _CallablePackage
