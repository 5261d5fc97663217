//! Tests of the detectors: work image, contrast blobs, motion, verification.

use super::*;

fn rgb_header(w: u32, h: u32) -> FrameHeader {
    let mut hd = FrameHeader::default();
    hd.set_geometry(PixelFormat::Rgb24, w, h, w * 3);
    hd.payload_len = w * h * 3;
    hd
}

fn grey_frame(w: u32, h: u32, v: u8) -> Vec<u8> {
    vec![v; (w * h * 3) as usize]
}

fn paint(buf: &mut [u8], w: u32, x0: u32, y0: u32, side: u32, rgb: [u8; 3]) {
    for y in y0..y0 + side {
        for x in x0..x0 + side {
            let i = ((y * w + x) * 3) as usize;
            buf[i..i + 3].copy_from_slice(&rgb);
        }
    }
}

#[test]
fn iou_and_wire() {
    let a = PixelBox {
        x: 0.0,
        y: 0.0,
        w: 10.0,
        h: 10.0,
    };
    let b = PixelBox { x: 5.0, ..a };
    assert!((a.iou(&a) - 1.0).abs() < 1e-6);
    assert!((a.iou(&b) - 50.0 / 150.0).abs() < 1e-6);
    assert_eq!(a.iou(&PixelBox { x: 20.0, ..a }), 0.0);
    assert_eq!(a.iou(&PixelBox::default()), 0.0);
    let c = PixelBox {
        x: -3.0,
        y: 2.6,
        w: 70000.0,
        h: f32::NAN,
    };
    assert_eq!(c.to_wire(), [0, 3, 65535, 0]);
}

#[test]
fn bad_frames_are_refused() {
    let hd = rgb_header(64, 48);
    assert!(WorkImage::from_frame(&hd, &[0; 100], 32).is_err());
    let mut bad = hd;
    bad.pixel_format = 77;
    assert!(WorkImage::from_frame(&bad, &grey_frame(64, 48, 0), 32).is_err());
    let mut bad = hd;
    bad.stride = 10;
    assert!(WorkImage::from_frame(&bad, &grey_frame(64, 48, 0), 32).is_err());
    assert!(WorkImage::from_frame(&hd, &grey_frame(64, 48, 0), 0).is_err());
    let flat = rgb_header(9, 2);
    assert!(WorkImage::from_frame(&flat, &grey_frame(9, 2, 0), 1).is_err());
    let mut nv = FrameHeader::default();
    nv.set_geometry(PixelFormat::Nv12, 63, 48, 64);
    assert!(WorkImage::from_frame(&nv, &[0; 64 * 72], 32).is_err());
    assert!(matches!(
        Detector::new("yolo", DetectorConfig::default()),
        Err(DetectError::UnknownModel(_))
    ));
}

#[test]
fn reduces_by_an_integer_factor() {
    let hd = rgb_header(100, 60);
    let img = WorkImage::from_frame(&hd, &grey_frame(100, 60, 200), 30).unwrap();
    assert_eq!(img.scale(), 4);
    assert_eq!((img.width(), img.height()), (25, 15));
    assert!(img.luma().iter().all(|&v| (199..=200).contains(&v)));
}

#[test]
fn nv12_and_rgb_agree() {
    let (w, h) = (320u32, 240u32);
    let mut rgb = grey_frame(w, h, 110);
    paint(&mut rgb, w, 120, 80, 16, [220, 40, 40]);
    let mut nv = vec![0u8; (w * h * 3 / 2) as usize];
    for y in 0..h {
        for x in 0..w {
            let i = ((y * w + x) * 3) as usize;
            let (r, g, b) = (rgb[i] as f32, rgb[i + 1] as f32, rgb[i + 2] as f32);
            nv[(y * w + x) as usize] = (0.299 * r + 0.587 * g + 0.114 * b) as u8;
            if x % 2 == 0 && y % 2 == 0 {
                let c = (w * h + (y / 2) * w + x) as usize;
                nv[c] = (128.0 - 0.1687 * r - 0.3313 * g + 0.5 * b) as u8;
                nv[c + 1] = (128.0 + 0.5 * r - 0.4187 * g - 0.0813 * b) as u8;
            }
        }
    }
    let mut hn = FrameHeader::default();
    hn.set_geometry(PixelFormat::Nv12, w, h, w);
    let a = WorkImage::from_frame(&rgb_header(w, h), &rgb, 160).unwrap();
    let b = WorkImage::from_frame(&hn, &nv, 160).unwrap();
    let mut det = Detector::new("contrast-blob", DetectorConfig::default()).unwrap();
    let da = det.scan(&a);
    let db = det.scan(&b);
    assert_eq!(da.len(), 1, "{da:?}");
    assert_eq!(db.len(), 1, "{db:?}");
    assert!(da[0].bbox.iou(&db[0].bbox) > 0.8);
}

#[test]
fn contrast_blob_finds_a_coloured_square_and_not_a_flat_image() {
    let (w, h) = (320u32, 240u32);
    let mut det = Detector::new("contrast-blob", DetectorConfig::default()).unwrap();
    let flat = grey_frame(w, h, 120);
    let img = WorkImage::from_frame(&rgb_header(w, h), &flat, 160).unwrap();
    assert!(det.scan(&img).is_empty());
    let mut f = flat.clone();
    paint(&mut f, w, 100, 60, 20, [40, 70, 220]);
    let img = WorkImage::from_frame(&rgb_header(w, h), &f, 160).unwrap();
    let hits = det.scan(&img);
    assert_eq!(hits.len(), 1, "{hits:?}");
    let (cx, cy) = hits[0].bbox.center();
    assert!(
        (cx - 110.0).abs() <= 2.0 && (cy - 70.0).abs() <= 2.0,
        "{hits:?}"
    );
    assert!(hits[0].confidence > 0.5);
    assert_eq!(hits[0].model, 0);
    // verify finds it near its box, not far away.
    let near = PixelBox {
        x: 95.0,
        y: 58.0,
        w: 20.0,
        h: 20.0,
    };
    assert!(det.verify(&img, &near).is_some());
    let far = PixelBox { x: 250.0, ..near };
    assert!(det.verify(&img, &far).is_none());
}

#[test]
fn contrast_blob_rejects_lines_and_tiny_specks() {
    let (w, h) = (320u32, 240u32);
    let mut f = grey_frame(w, h, 100);
    for y in 0..h {
        for x in 150..156 {
            let i = ((y * w + x) * 3) as usize;
            f[i..i + 3].copy_from_slice(&[220, 220, 220]);
        }
    }
    paint(&mut f, w, 40, 40, 3, [255, 0, 0]);
    let img = WorkImage::from_frame(&rgb_header(w, h), &f, 320).unwrap();
    let mut det = Detector::new("contrast-blob", DetectorConfig::default()).unwrap();
    assert!(det.scan(&img).is_empty());
}

#[test]
fn motion_bg_warms_up_then_sees_a_moving_square() {
    let (w, h) = (320u32, 240u32);
    let mut det = Detector::new("motion-bg", DetectorConfig::default()).unwrap();
    assert_eq!(det.model(), 1);
    let base = grey_frame(w, h, 90);
    // A square is there from the start: nothing until the warm-up is over.
    for i in 0..MOTION_WARMUP_FRAMES - 1 {
        let mut f = base.clone();
        paint(&mut f, w, 200 + i * 4, 40, 16, [200, 200, 60]);
        let img = WorkImage::from_frame(&rgb_header(w, h), &f, 160).unwrap();
        assert!(det.scan(&img).is_empty(), "frame {i}");
    }
    // Then one drives in from the left.
    for i in 0..10u32 {
        let mut f = base.clone();
        let x = 40 + i * 6;
        paint(&mut f, w, x, 150, 16, [200, 200, 60]);
        let img = WorkImage::from_frame(&rgb_header(w, h), &f, 160).unwrap();
        let hits = det.scan(&img);
        let on_it: Vec<_> = hits.iter().filter(|d| d.bbox.y > 120.0).collect();
        assert_eq!(on_it.len(), 1, "frame {i}: {hits:?}");
        let (cx, cy) = on_it[0].bbox.center();
        assert!((cx - (x + 8) as f32).abs() < 4.0, "frame {i}: {hits:?}");
        assert!((cy - 158.0).abs() < 4.0, "frame {i}: {hits:?}");
    }
}
