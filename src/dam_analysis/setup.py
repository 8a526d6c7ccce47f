import os

from setuptools import find_packages, setup

PACKAGE_NAME = 'dam_analysis'
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
            'check_lift_server = dam_analysis.entry_points:check_lift_server',
            'check_lift = dam_analysis.entry_points:check_lift',
            'lift_map = dam_analysis.lift_map:entry_point',
            'scale_map = dam_analysis.scale_map:entry_point',
            'csm_dependence = dam_analysis.entry_points:csm_dependence',
            'plan_lift = dam_analysis.entry_points:plan_lift',
        ],
    },
)
