import os
from glob import glob

from setuptools import find_packages, setup

package_name = 'humanoid_planner'


def files(pattern):
    return sorted(f for f in glob(pattern) if os.path.isfile(f))


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        (os.path.join('share', package_name, 'config'), files('config/*.yaml')),
        (os.path.join('share', package_name, 'config', 'robots'), files('config/robots/*')),
        (os.path.join('share', package_name, 'config', 'examples'), files('config/examples/*.yaml')),
    ],
    package_data={package_name: ['py.typed']},
    # Runtime libraries of the core (the ROS packages come from the ROS install or the PyPI wheels of
    # requirements.txt, which pins the exact versions tested; colcon builds do not install these).
    install_requires=['setuptools', 'numpy', 'numba', 'scipy', 'python-fcl', 'trimesh', 'yourdfpy', 'lxml', 'toppra',
                      'PyYAML', 'matplotlib'],
    zip_safe=True,
    maintainer='humanoid_planner maintainers',
    maintainer_email='maintainers@humanoid-planner.dev',
    description='Reach-to-grasp motion planning (GIRRT, DAGRRT) for humanoid arms, as a ROS 2 node.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'planner_node = humanoid_planner.node_main:main',
            'grasp_client = humanoid_planner.ros.grasp_client:main',
            'planner_demo = humanoid_planner.demo:main',
            'planner_setup = humanoid_planner.planner_setup:main',
        ],
    },
)
