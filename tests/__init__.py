"""The tests of the four packages, a package itself so that pytest (its default ``prepend``
import mode) names every test module by its full name (``tests.device.test_usb``) from the
repository's root, and test modules import the helpers of :mod:`tests.helpers` by name."""
