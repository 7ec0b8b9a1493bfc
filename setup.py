"""ament_python packaging of flexlink_ros (also installable with `pip install .`)."""

from glob import glob

from setuptools import Extension, find_packages, setup

package_name = 'flexlink_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    # The streaming estimator's per-sample step in C (plain C API, no numpy headers); the
    # package falls back to its numpy step when the extension is not built.
    # Both include the validity indicator's kernel (_nonlinearity.h).
    ext_modules=[Extension('flexlink_ros.core.estimation._radau_step',
                           ['flexlink_ros/core/estimation/_radau_step.c'],
                           depends=['flexlink_ros/core/estimation/_nonlinearity.h',
                                    'flexlink_ros/core/estimation/_pivot.h'],
                           extra_compile_args=['-O3']),
                 # the validity indicator per sample (its Python twin serves where not built)
                 Extension('flexlink_ros.core.estimation._nonlinearity',
                           ['flexlink_ros/core/estimation/_nonlinearity.c'],
                           depends=['flexlink_ros/core/estimation/_nonlinearity.h',
                                    'flexlink_ros/core/estimation/_doubles.h'],
                           extra_compile_args=['-O3']),
                 # the dynamic second-order pass's loads per sample (numpy twin where not built)
                 Extension('flexlink_ros.core.estimation._second_order_dynamic',
                           ['flexlink_ros/core/estimation/_second_order_dynamic.c'],
                           depends=['flexlink_ros/core/estimation/_doubles.h'],
                           extra_compile_args=['-O3']),
                 # the reduced nonlinear model's Newton step (numpy twin where not built)
                 Extension('flexlink_ros.core.estimation._nonlinear_step',
                           ['flexlink_ros/core/estimation/_nonlinear_step.c'],
                           depends=['flexlink_ros/core/estimation/_doubles.h',
                                    'flexlink_ros/core/estimation/_pivot.h'],
                           # its dot products split into vector lanes (no OpenMP runtime)
                           extra_compile_args=['-O3', '-fopenmp-simd'])],
    install_requires=['setuptools'],
    # The geometrically nonlinear peer the linear model is checked against (studies/), and
    # Ray for `flexlink fleet` (many bags recomputed, one task per bag).
    extras_require={'peer': ['exudyn==1.13.6'], 'fleet': ['ray[data]==2.60.0']},
    zip_safe=False,
    maintainer='flexlink_ros developers',
    maintainer_email='flexlink@example.com',
    description='Elastic deflection and joint-contact estimates of a flexible four-bar linkage',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'flexlink = flexlink_ros.cli.main:run',
            'crank_driver = flexlink_ros.ros.crank_driver:main',
            'flexlink_node = flexlink_ros.ros.node:main',
        ],
    },
)
