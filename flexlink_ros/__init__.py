"""flexlink_ros: elastic deflection and joint-contact estimates of a flexible four-bar linkage."""

# The package's version: `flexlink --version` prints it; setup.py and package.xml carry the
# same number (test/cli/test_main.py keeps the three, and the installed metadata, equal).
__version__ = '0.1.0'
