"""The camera chain: every effect of the camera on a rendered frame, one stage module each, in the
order light travels (``order`` strings them together; read the order there):

``lens`` (distortion, pixel aspect, chromatic aberration) -> ``light`` (exposure, vignetting,
veiling glare) -> ``plain_sensor``, or a colour camera's ``colour_sensor`` (``cfa``, ``emva``) ->
``isp`` (white balance, ``demosaic``, colour correction, gain, tone, denoise, sharpening) ->
``encoding`` (JPEG). A new effect is a function in its stage's module, called by that stage.

Importing the package imports none of its modules (``core.scene`` and ``core.config`` import stage
modules, which import ``core.scene``): each name below is imported from its module on first use
(PEP 562). ``capture`` runs the whole chain; ``expose_frame`` the stages between lens and encoding;
``develop`` a colour camera's sensor and ISP; ``develop_raw`` the ISP of a real camera's raw frame.
"""

__all__ = [
    # the chain, and the part of it between the lens and the encoding
    "capture", "Capture", "expose_frame",
    # stages and their types
    "resample_passes", "RenderPasses", "develop", "ColourChain", "develop_raw", "jpeg_round_trip",
]

_OWNERS = {"capture": "order", "Capture": "order", "expose_frame": "order", "develop": "order",
           "resample_passes": "lens", "RenderPasses": "lens", "ColourChain": "colour_sensor",
           "develop_raw": "isp", "jpeg_round_trip": "encoding"}


def __getattr__(name: str):
    """The facade's names, imported from their module on first use (PEP 562)."""
    owner = _OWNERS.get(name)
    if owner == "order":
        from dockfactory.core.camera_chain import order as module
    elif owner == "lens":
        from dockfactory.core.camera_chain import lens as module
    elif owner == "colour_sensor":
        from dockfactory.core.camera_chain import colour_sensor as module
    elif owner == "isp":
        from dockfactory.core.camera_chain import isp as module
    elif owner == "encoding":
        from dockfactory.core.camera_chain import encoding as module
    else:
        raise AttributeError(f"module 'dockfactory.core.camera_chain' has no attribute {name!r}")
    value = getattr(module, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
