import os

from setuptools import find_packages, setup

PACKAGE_NAME = 'dam_hand_driver'
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
            'hand_driver = dam_hand_driver.entry_points:hand_driver',
            'hand_urdf = dam_hand_driver.urdf:main',
            'dam_state_publisher = dam_hand_driver.entry_points:dam_state_publisher',
            'dynamixel_setup = dam_hand_driver.dynamixel_setup:main',
        ],
    },
)
