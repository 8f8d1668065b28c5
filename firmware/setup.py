# catkin setup: installs the pure-Python module in python/chefbot_firmware.
from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=["chefbot_firmware"], package_dir={"": "python"}))
