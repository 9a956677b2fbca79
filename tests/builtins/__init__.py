"""Tests of the built-in plugins (hcard_builtins): the image encoder and the physics predictors
(ultrasonic, electrovibration, finger friction, coupled) against the thesis."""
