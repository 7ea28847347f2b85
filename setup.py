"""Python package metadata. Under catkin (catkin_python_setup) the metadata comes from package.xml;
without catkin, ``pip install -e .`` installs the ROS-free core (src/locem_bridge)."""
try:
    from catkin_pkg.python_setup import generate_distutils_setup
except ImportError:  # plain pip install, no catkin
    generate_distutils_setup = None

import os

from setuptools import find_packages, setup

PACKAGES = find_packages(os.path.join(os.path.dirname(os.path.abspath(__file__)), "src"))
PACKAGE_DATA = {"locem_bridge.hmi": ["static/*"]}  # the operator page (HTML, JS, CSS)

if generate_distutils_setup is not None:
    setup(**generate_distutils_setup(packages=PACKAGES, package_dir={"": "src"}, package_data=PACKAGE_DATA))
else:
    setup(name="locem_bridge", version="0.1.0", packages=PACKAGES, package_dir={"": "src"}, package_data=PACKAGE_DATA,
          python_requires=">=3.8")
