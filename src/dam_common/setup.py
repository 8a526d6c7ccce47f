import os
from glob import glob

from setuptools import find_packages, setup

PACKAGE_NAME = 'dam_common'
HERE = os.path.dirname(os.path.abspath(__file__))

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
        # The single source of truth config/ at the repository root, installed for `ros2 run`.
        # Paths relative to this file, as colcon requires.
        ('share/' + PACKAGE_NAME + '/config',
         sorted(os.path.relpath(p, HERE)
                for p in glob(os.path.join(HERE, '..', '..', 'config', '*.yaml')))),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='DAM hand maintainers',
    maintainer_email='maintainers@dam-hand.org',
    description=open(os.path.join(HERE, 'package.xml')).read().split('<description>')[1]
    .split('</description>')[0],
    license='Apache-2.0',
    entry_points={'console_scripts': []},
)
