"""Built-in physics predictors (thesis chapters 1-4): ultrasonic, electrovibration, finger
friction and the coupled UV+EV model."""
