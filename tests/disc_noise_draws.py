"""Centre noise drawn as the disc noise model says a camera has it (tests only): each centre's
covariance shaped by its disc's image (solver.disc_noise.section_noise_shapes), so that synthetic
frames carry the noise the solver's weights and gates assume, not an even noise over thin and
round discs alike."""
import numpy as np

from dockfactory.solver.disc_noise import section_noise_shapes


def disc_noise(sc, markers, noise_px: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 2) px: noise of the synthetic docking scene ``sc``'s markers (``markers``: its layout,
    section A's centres first, then B's, as ``sc.uv_a``, ``sc.uv_b``), ``noise_px`` per axis averaged
    over them, drawn from ``rng``."""
    shapes = np.concatenate([section_noise_shapes([m for m in markers if m.section == s], cam, sc.focal_px)
                             for s, cam in (("A", sc.cam_from_d), ("B", sc.cam_from_b))])
    shapes *= noise_px ** 2 / (np.trace(shapes, axis1=1, axis2=2).mean() / 2.0)
    return np.einsum("nij,nj->ni", np.linalg.cholesky(shapes), rng.standard_normal((len(shapes), 2)))
