"""One flight: configuration, perching frame, estimator, controller, supervisor and the loop that runs them."""
