"""A rendered dataset as a folder: open it, check it, describe, compare, export and publish it.

Importing the package imports none of its modules (PEP 562: each name below is imported from its
module when first used), so a module of this room that needs another one's helper never loads
the whole room. The modules: ``folder`` (identity, locks, frame completeness, the manifest),
``reader`` (the :class:`Dataset` contract every consumer reads), ``check`` (verify), ``tools``
(info, export), ``diff``, ``card`` (README.md), ``hf_view``, ``dvc_links``, ``published`` with
``fingerprints``, ``fingerprints_libm``, ``label_prints``, ``label_legacy`` and ``marker_check``
(a re-render checked against a published manifest).
"""

__all__ = [
    "Dataset", "DatasetError", "verify_dataset", "dataset_info", "export_dataset", "diff_datasets",
    "write_card", "write_hf_view", "publish_dataset", "verify_against_manifest",
]


def __getattr__(name: str):
    """The facade's names, imported from their module on first use (PEP 562)."""
    if name == "Dataset":
        from dockfactory.generator.datasets.reader import Dataset as value
    elif name == "DatasetError":
        from dockfactory.generator.datasets.folder import DatasetError as value
    elif name == "verify_dataset":
        from dockfactory.generator.datasets.check import verify as value
    elif name == "dataset_info":
        from dockfactory.generator.datasets.tools import info as value
    elif name == "export_dataset":
        from dockfactory.generator.datasets.tools import export as value
    elif name == "diff_datasets":
        from dockfactory.generator.datasets.diff import diff as value
    elif name == "write_card":
        from dockfactory.generator.datasets.card import write_card as value
    elif name == "write_hf_view":
        from dockfactory.generator.datasets.hf_view import write_hf_view as value
    elif name == "publish_dataset":
        from dockfactory.generator.datasets.published import publish as value
    elif name == "verify_against_manifest":
        from dockfactory.generator.datasets.published import verify_against as value
    else:
        raise AttributeError(f"module 'dockfactory.generator.datasets' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
