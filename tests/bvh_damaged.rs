mod common;
use motionforge::motion::*;

#[test]
fn deep() {
    for depth in [1000usize, 10_000, 100_000] {
        let mut s = String::from("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 0\n");
        for _ in 0..depth {
            s.push_str("JOINT b\n{\nOFFSET 0 0 0\nCHANNELS 0\n");
        }
        let r = read_bvh(&s);
        println!("{depth}: {:?}", r.err());
    }
}

#[test]
fn huge_frames() {
    let s = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\nEnd Site\n{\nOFFSET 0 0 1\n}\n}\nMOTION\nFrames: 1e12\nFrame Time: 0.03\n1 2 3\n";
    println!("{:?}", read_bvh(s).err());
}

#[test]
fn no_newline_truncated() {
    let s = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n}\nMOTION\nFrames: 2\nFrame Time: 0.03";
    println!("lines {} {:?}", s.lines().count(), read_bvh(s).err());
    let s = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n}\nMOTION\nFrames: 2\nFrame Time: 1e-320\n1 2 3\n4 5 6\n";
    println!("{:?}", read_bvh(s).map(|b| b.header_fps));
}
