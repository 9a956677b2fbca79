"""What the tests share that is not a fixture: cards, hostile inputs, independent references
(a double-precision renderer, the plate loop's response, calibration recordings), the device
served in another process, real-time runs, clients of the USB/IP server, and the running of
``hcard`` (:mod:`tests.helpers.cli`). Imported by name (``from tests.helpers.cards import
two_texture_card``); tests/conftest.py has pytest rewrite their asserts like a test's."""
