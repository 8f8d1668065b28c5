# Generated-style catkin setup: installs the pure-Python module in src/chefbot_fleet.
from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=["chefbot_fleet"], package_dir={"": "src"}))
