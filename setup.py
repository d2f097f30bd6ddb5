"""ament_python package: builds with colcon in a ROS 2 Jazzy workspace and installs with pip."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "ipe_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*", "msg_bridge", "msg_bridge.*"]),
    package_data={PACKAGE: ["data/*.json", "schema/*.json", "ros/fastdds_node.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/examples", glob("ipe_ros/data/*.json")),
        (f"share/{PACKAGE}/config", ["config/ipe.yaml"]),
        (f"share/{PACKAGE}/schema", glob("ipe_ros/schema/*.json")),
        (f"share/{PACKAGE}/launch", ["launch/ipe.launch.py"]),
    ],
    python_requires=">=3.11",
    install_requires=["setuptools", "numpy", "pybullet", "scipy", "tqdm", "trimesh", "coacd"],
    zip_safe=True,
    maintainer="ipe_ros maintainers",
    maintainer_email="ipe-ros@example.com",
    description="The intuitive physics engine (Battaglia et al. 2013) as a ROS 2 service",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "ipe = ipe_ros.cli:main",
            "ipe_node = ipe_ros.ros.node:main",
            "ipe_lifecycle_node = ipe_ros.ros.lifecycle:lifecycle_main",
            "ipe_ros_demo = ipe_ros.ros.demo:main",
            "ipe_send_scene = ipe_ros.ros.send_scene:main",
        ],
    },
)
