"""Layer fixture (never imported): a lazy facade (PEP 562) may import its own modules in its
``__getattr__``, nothing else there."""


def __getattr__(name):
    if name == "run":
        from dockfactory.generator.worker import run as value   # fine: its own module, lazily
    else:
        from dockfactory.core.geometry import norm as value     # VIOLATION: not its own module
    return value
