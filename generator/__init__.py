"""The dataset factory (sampler, labels, render jobs, dataset checks, tools and card),
behind a small facade.

Importing the package imports no other module: render workers import it, where the dataset tools
must not load (and an eager facade would make import cycles). Each name is imported from its module
when first used (PEP 562): ``run_render`` and ``JobOptions`` (:mod:`~dockfactory.generator.render_job`),
and the dataset room's (:mod:`~dockfactory.generator.datasets`): ``Dataset``, ``verify_dataset``,
``export_dataset``, ``dataset_info``, ``diff_datasets``, ``write_card``.
"""

__all__ = [
    # rendering a dataset
    "run_render", "JobOptions",
    # reading, checking, describing, comparing and exporting a dataset; its card
    "Dataset", "verify_dataset", "dataset_info", "diff_datasets", "export_dataset", "write_card",
]


ROOM_NAMES = ("Dataset", "verify_dataset", "dataset_info", "diff_datasets", "export_dataset", "write_card")


def __getattr__(name: str):
    """The facade's names, imported from their module on first use (PEP 562)."""
    if name == "run_render":
        from dockfactory.generator.render_job import run_render as value
    elif name == "JobOptions":
        from dockfactory.generator.render_job import JobOptions as value
    elif name in ROOM_NAMES:
        from dockfactory.generator import datasets
        value = getattr(datasets, name)
    else:
        raise AttributeError(f"module 'dockfactory.generator' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
