"""solver.identify._explained: which of two section identifications the centre noise explains.
A rival whose joint fit is many times the best one's is no explanation, also when the camera is
noisier than its card (every fit above the card's noise): before, the search then kept both and
refused the frame as ambiguous (a painted test camera at 7x the card, 0.10 px against 1.22 px)."""
from dockfactory.solver.identify import _explained


class _H:
    def __init__(self, n):
        self.pairs = {i: i for i in range(n)}


def test_a_rival_far_beyond_the_best_fit_is_no_explanation_at_any_card():
    best, rival = _H(7), _H(7)
    for card in (0.05, 0.0135, 0.002):                  # the best fit 0.10 px: within, 7x and 50x the card
        kept = _explained([(0.10, best), (1.22, rival)], 7, card)
        assert [h for _, h in kept] == [best], card


def test_two_fits_alike_stay_ambiguous_and_no_card_keeps_both():
    a, b = _H(7), _H(7)
    assert len(_explained([(0.10, a), (0.11, b)], 7, 0.0135)) == 2     # both explained at the best's noise
    assert len(_explained([(0.010, a), (0.011, b)], 7, 0.0135)) == 2    # both explained at the card
    assert len(_explained([(0.10, a), (1.22, b)], 7, None)) == 2        # no known noise: nothing to judge by
