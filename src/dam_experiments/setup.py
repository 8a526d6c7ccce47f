import os

from setuptools import find_packages, setup

PACKAGE_NAME = 'dam_experiments'
HERE = os.path.dirname(os.path.abspath(__file__))

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='DAM hand maintainers',
    maintainer_email='maintainers@dam-hand.org',
    description=open(os.path.join(HERE, 'package.xml')).read().split('<description>')[1]
    .split('</description>')[0],
    license='Apache-2.0',
    entry_points={
        # Executables land in lib/<package>/ (setup.cfg), where `ros2 run` looks for them.
        'console_scripts': [
            'dam_experiment = dam_experiments.entry_points:dam_experiment',
            'sweep = dam_experiments.entry_points:sweep',
            'sweep_plot = dam_experiments.entry_points:sweep_plot',
            'sweep_report = dam_experiments.entry_points:sweep_report',
            'calibrate_csm = dam_experiments.entry_points:calibrate_csm',
        ],
    },
)
