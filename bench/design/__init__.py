"""Design: the design predictor's card, its check against renders, its speed."""
