# Generated-style catkin setup: installs the pure-Python module in src/chefbot_navigation.
from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=["chefbot_navigation", "chefbot_navigation.amcl",
                                           "chefbot_navigation.slam"], package_dir={"": "src"}))
